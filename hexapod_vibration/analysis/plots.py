"""PNG figures of an analysed bag (matplotlib, Agg backend: no display needed).

- ``spectra.png``: z-axis power spectra, uncontrolled vs controlled (paper Figs. 5-8).
- ``plant_response.png``: z-axis acceleration over a few periods and its spectrum
  (paper Fig. 4).
- ``convergence.png``: the tones' envelopes around control-on and the notch weights.
- ``pointing.png``: the top plate's pose from the eddy-current sensors.
"""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from hexapod_vibration.analysis.report import FS, Analysis, BagSignals  # noqa: E402
from hexapod_vibration.core import spectrum  # noqa: E402
from hexapod_vibration.core.model.config import ModelConfig  # noqa: E402
from hexapod_vibration.core.model.sensors import EddySensorArray  # noqa: E402

G0 = spectrum.G0


def write_all(out: Path, signals: BagSignals, result: Analysis, model: ModelConfig) -> list[Path]:
    """Write every figure that the bag's content allows; return their paths."""
    paths = [spectra_figure(out / "spectra.png", result),
             plant_response_figure(out / "plant_response.png", result)]
    if signals.control_on_sample is not None:
        paths.append(convergence_figure(out / "convergence.png", signals, result))
    if "/pph/eddy" in signals.series and len(signals.series["/pph/eddy"]):
        paths.append(pointing_figure(out / "pointing.png", signals, model))
    return paths


def _psd_db(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    f, psd = spectrum.power_spectral_density(x - x.mean(), FS,
                                             segment_s=min(10.0, x.size / FS))
    return f, 10.0 * np.log10(np.maximum(psd, 1e-30) / G0**2)


def _mark_tones(ax: plt.Axes, result: Analysis) -> None:
    for row in result.report["tones"]:
        ax.axvline(row["frequency_hz"], color="0.8" if not row["controlled"] else "tab:red",
                   lw=0.8, ls="--", zorder=0)


def spectra_figure(path: Path, result: Analysis) -> Path:
    """Uncontrolled and controlled power spectral density of the z-axis acceleration."""
    fig, ax = plt.subplots(figsize=(9, 4.5))
    for name, color in (("uncontrolled", "tab:blue"), ("controlled", "tab:orange")):
        rows = result.windows.get(name)
        if rows is None or rows.stop - rows.start < 16:
            continue
        f, db = _psd_db(result.z[rows])
        ax.plot(f, db, color=color, lw=0.8, label=f"{name} ({(rows.stop - rows.start) / FS:.0f} s)")
    _mark_tones(ax, result)
    top = max(r["frequency_hz"] for r in result.report["tones"]) if result.report["tones"] else 100
    ax.set(xlim=(0, min(FS / 2, max(150.0, 1.5 * top))), xlabel="frequency (Hz)",
           ylabel="PSD (dB re 1 g$^2$/Hz)",
           title=f"{result.report['scenario']}: top plate z-axis acceleration")
    ax.grid(alpha=0.3)
    ax.legend()
    return _save(fig, path)


def plant_response_figure(path: Path, result: Analysis) -> Path:
    """Time trace (0.1 s) and spectrum of the uncontrolled z-axis acceleration."""
    rows = result.windows["uncontrolled"]
    x = result.z[rows]
    fig, (ax_t, ax_f) = plt.subplots(1, 2, figsize=(11, 4))
    seg = x[-100:] - x.mean()
    ax_t.plot(np.arange(seg.size) / FS * 1e3, seg / G0 * 1e3, lw=1.0)
    ax_t.set(xlabel="time (ms)", ylabel="z acceleration (mg, DC removed)",
             title="plant response (last 0.1 s of the window)")
    f, db = _psd_db(x)
    ax_f.plot(f, db, lw=0.8)
    _mark_tones(ax_f, result)
    ax_f.set(xlabel="frequency (Hz)", ylabel="PSD (dB re 1 g$^2$/Hz)", xlim=(0, FS / 2),
             title="spectrum: harmonics of the response")
    for ax in (ax_t, ax_f):
        ax.grid(alpha=0.3)
    return _save(fig, path)


def convergence_figure(path: Path, signals: BagSignals, result: Analysis) -> Path:
    """Tone envelopes (dB re 1 g) around control-on and the notch weights' magnitudes."""
    index = signals.accel.sample_index
    on = signals.control_on_sample
    start = int(np.searchsorted(index, on - 2 * int(FS)))
    z = result.z[start:]
    t0 = index[start] / FS
    fig, (ax_e, ax_w) = plt.subplots(2, 1, figsize=(9, 6.5), sharex=True)
    for row in result.report["tones"]:
        t, env = spectrum.tone_envelope(z, FS, row["frequency_hz"])
        ax_e.plot(t + t0, 20 * np.log10(np.maximum(env, 1e-15) / G0),
                  lw=1.0, label=f"{row['frequency_hz']:g} Hz")
    ax_e.axvline(on / FS, color="k", lw=0.8, ls="--", label="control on")
    ax_e.set(ylabel="tone level (dB re 1 g)", title="convergence of the notch controller")
    ax_e.legend(ncol=3, fontsize=8)
    if signals.weights.size:
        keep = signals.weights_index >= index[start]
        t_w = signals.weights_index[keep] / FS
        magnitude = np.hypot(signals.weights[keep, ..., 0], signals.weights[keep, ..., 1])
        tones = signals.notch_tones() or list(range(magnitude.shape[1]))
        for k in range(magnitude.shape[1]):
            for strut in range(6):
                ax_w.plot(t_w, magnitude[:, k, strut], lw=0.7, color=f"C{k}",
                          label=f"{tones[k]:g} Hz" if strut == 0 else None)
        ax_w.legend(fontsize=8)
    ax_w.set(xlabel="sim time (s)", ylabel="|W| per strut (N)")
    for ax in (ax_e, ax_w):
        ax.grid(alpha=0.3)
    return _save(fig, path)


def pointing_figure(path: Path, signals: BagSignals, model: ModelConfig) -> Path:
    """Tilts, twist (deg) and z (um) of the top plate from the eddy-current sensors."""
    eddy = signals.series["/pph/eddy"]
    height = float(model.geometry.top_joints_m[0, 2])
    pose = EddySensorArray(model.eddy, height).pose(eddy.values)
    t = eddy.sample_index / FS
    fig, (ax_a, ax_z) = plt.subplots(2, 1, figsize=(9, 5.5), sharex=True)
    for k, name in ((3, "tilt x"), (4, "tilt y"), (5, "twist")):
        ax_a.plot(t, np.rad2deg(pose[:, k]), lw=0.8, label=name)
    ax_a.set(ylabel="angle (deg)", title="pointing: pose from the eddy-current sensors")
    ax_a.legend()
    ax_z.plot(t, pose[:, 2] * 1e6, lw=0.8, color="tab:green")
    ax_z.set(xlabel="sim time (s)", ylabel="z (um)")
    for ax in (ax_a, ax_z):
        ax.grid(alpha=0.3)
    return _save(fig, path)


def _save(fig: plt.Figure, path: Path) -> Path:
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path
