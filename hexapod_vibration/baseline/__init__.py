"""Reference controllers the notch canceller is compared with (FxLMS, compiled kernels)."""
