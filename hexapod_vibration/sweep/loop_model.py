"""The plant the notch canceller sees, as a discrete LTI model at the loop rate.

Built from the physical model's linear part (:class:`LinearHexapodModel`, the
``nonlinear: false`` plant: no free-play, constant force constant), sample by sample as
:class:`~hexapod_vibration.core.model.plant.PPHPlant` and the core loop step it:

- mechanics discretised exactly (zero-order hold) at the internal rate (10 kHz), the strut
  forces held over the 1 ms sample; the accelerometers' axial specific force at the end of
  each internal step goes through the anti-aliasing filter at the internal rate, and the
  reading of sample n+1 is the filter's output at the last internal step of sample n;
- the pointing loop closed (:meth:`PointingController.linear_state_space`, eddy gaps of
  the relative pose at the start of each sample, no anti-windup), its forces added to the
  notch command;
- the DC blocker of the control path (:class:`DCBlocker`).

So ``x_{n+1} = A x_n + B u_n``, ``e_n = C x_n`` with u the notch command (N, 6) and e the
six DC-blocked accelerations (m/s^2): the one-sample command hold of
:func:`~hexapod_vibration.core.control.adaptation.closed_loop_spectral_radius`. Noise,
quantisation, clipping and saturation are left out (they are not linear).
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from scipy import signal

from hexapod_vibration.core.control.filters import DCBlocker
from hexapod_vibration.core.model.config import ModelConfig
from hexapod_vibration.core.model.plant import (
    IN_STRUT,
    N_DOF,
    LinearHexapodModel,
    discretize,
)
from hexapod_vibration.core.model.sensors import AccelerometerBank, EddySensorArray
from hexapod_vibration.core.sim.closed_loop import STRUTS, make_pointing_controller

StateSpace = tuple[np.ndarray, np.ndarray, np.ndarray]


def _internal_step(config: ModelConfig) -> tuple[np.ndarray, ...]:
    """(Phi, Gamma, H, J) of one internal step: mechanics plus anti-aliasing filter.

    State ``s = [mechanical state (36), filter states (6 x order)]``, input the held strut
    forces: ``s_{k+1} = Phi s_k + Gamma u``; the filtered reading at step k is ``H s_k + J u``.
    """
    sim = config.simulation
    model = LinearHexapodModel(config)
    a, b = model.state_space()
    ad, bd = discretize(a, b[:, IN_STRUT], 1.0 / sim.internal_rate_hz)
    rows = slice(N_DOF + 12, N_DOF + 18)           # axial accelerations of the moving parts
    acc_x, acc_u = a[rows], b[rows, IN_STRUT]
    bank = AccelerometerBank(config.accelerometer, sim.internal_rate_hz, sim.sample_rate_hz)
    fa, fb, fc, fd = signal.tf2ss(*bank.antialias_ba)
    eye = np.eye(STRUTS)
    f_a, f_b, f_c, f_d = np.kron(eye, fa), np.kron(eye, fb), np.kron(eye, fc), fd[0, 0] * eye
    y_x, y_u = acc_x @ ad, acc_x @ bd + acc_u       # specific force at the step's end
    n_mech, n_filter = ad.shape[0], f_a.shape[0]
    phi = np.block([[ad, np.zeros((n_mech, n_filter))], [f_b @ y_x, f_a]])
    gamma = np.vstack([bd, f_b @ y_u])
    return phi, gamma, np.hstack([f_d @ y_x, f_c]), f_d @ y_u


def _one_sample(config: ModelConfig) -> tuple[np.ndarray, ...]:
    """(A_s, B_s, C_r, D_r): state over one sample and the reading it produces."""
    phi, gamma, h, j = _internal_step(config)
    substeps = config.simulation.substeps
    power, accumulated = np.eye(phi.shape[0]), np.zeros_like(gamma)
    for _ in range(substeps - 1):
        accumulated = accumulated + power @ gamma
        power = phi @ power
    reading_x, reading_u = h @ power, h @ accumulated + j
    return phi @ power, accumulated + power @ gamma, reading_x, reading_u


def canceller_plant(config: ModelConfig) -> StateSpace:
    """(A, B, C) at the loop rate from notch command (N) to DC-blocked accelerations (m/s^2).

    ``config`` is used as its linear reference plant (:meth:`ModelConfig.linear`). State
    ``[plant and filter (S), reading (6), pointing law (P), DC blocker (6)]``.
    """
    config = config.linear()
    fs = config.simulation.sample_rate_hz
    a_s, b_s, c_r, d_r = _one_sample(config)
    n_s = a_s.shape[0]
    height = float(config.geometry.top_joints_m[0, 2])
    sensing = EddySensorArray(config.eddy, height).sensing_matrix
    relative = np.zeros((6, n_s))
    relative[:, :6], relative[:, 6:12] = np.eye(6), -np.eye(6)     # q_top - q_bottom
    gaps = sensing @ relative
    p_a, p_b, p_c, p_d = make_pointing_controller(config, sensing, fs).linear_state_space()
    n_p = p_a.shape[0]
    r = DCBlocker(STRUTS, fs).r
    eye, z6 = np.eye(STRUTS), np.zeros((STRUTS, STRUTS))
    # applied force = u + pointing = u + p_c xi + p_d gaps S
    force_s, force_xi = p_d @ gaps, p_c
    a = np.block([
        [a_s + b_s @ force_s, np.zeros((n_s, STRUTS)), b_s @ force_xi, np.zeros((n_s, STRUTS))],
        [c_r + d_r @ force_s, z6, d_r @ force_xi, z6],
        [p_b @ gaps, np.zeros((n_p, STRUTS)), p_a, np.zeros((n_p, STRUTS))],
        [np.zeros((STRUTS, n_s)), (r - 1.0) * eye, np.zeros((STRUTS, n_p)), r * eye],
    ])
    b = np.vstack([b_s, d_r, np.zeros((n_p, STRUTS)), np.zeros((STRUTS, STRUTS))])
    c = np.hstack([np.zeros((STRUTS, n_s)), eye, np.zeros((STRUTS, n_p)), eye])
    return a, b, c


def frequency_response(plant: StateSpace, frequencies_hz: np.ndarray | list[float],
                       sample_rate_hz: float) -> np.ndarray:
    """``G[t] = C (e^{j w_t} I - A)^{-1} B`` (T, 6, 6): the phasor of e per phasor of u.

    The convention of :class:`ToneResponseIdentifier` (its G includes the command hold).
    """
    a, b, c = plant
    eye = np.eye(a.shape[0])
    return np.stack([c @ np.linalg.solve(np.exp(2j * np.pi * f / sample_rate_hz) * eye - a, b)
                     for f in np.atleast_1d(frequencies_hz)])


def response_function(plant: StateSpace, sample_rate_hz: float
                      ) -> Callable[[np.ndarray], np.ndarray]:
    """G as a function of frequency (Hz) -> (F, 6, 6), :func:`frequency_response`'s values.

    From the eigenvalues of A (one decomposition, then F x n products): what the Nyquist
    test of :mod:`~hexapod_vibration.core.control.sensitivity` evaluates thousands of
    times.
    """
    a, b, c = plant
    poles, vectors = np.linalg.eig(a)
    right = np.linalg.solve(vectors, b)
    left = c @ vectors

    def at(frequencies_hz: np.ndarray) -> np.ndarray:
        z = np.exp(2j * np.pi * np.atleast_1d(np.asarray(frequencies_hz, dtype=float))
                   / sample_rate_hz)
        return np.einsum("ik,fk,kj->fij", left, 1.0 / (z[:, None] - poles[None, :]), right)

    return at
