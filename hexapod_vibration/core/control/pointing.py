"""Low-pass pointing law: hold the top plate's pose from the eddy-current sensors.

Per sample (1 kHz): pose = S^-1 gaps (relative to the bottom plate); error = target - pose;
a Cartesian PID law per axis, then the Stewart statics, a Butterworth low-pass and the
actuator's range:

    wrench = Kp e + Ki integral(e) - D pose_rate,   strut forces = J^-T wrench,

each strut force saturated at +-``force_limit_n`` after the low-pass (the driver refuses a
command beyond the actuator's range: after a sag, say while the driver had zeroed this
stream, an unsaturated law asked for more, every command was refused and the platform never
came back), the integral held while its own strut forces would exceed it (anti-windup).

The cubic configuration decouples the six axes (J^T J and the payload's mass matrix are
diagonal), so each axis is a mass m on the suspension stiffness k = k_strut (J^T J)_ii.
The gains place that axis' closed-loop poles at

    (s + w_c)(s^2 + 2 zeta w_n s + w_n^2),   w_c = 2 pi bandwidth_hz,  w_n = max(w_r, 2 w_c)

with w_r = sqrt(k/m) the axis' suspension mode: the integral pole sets the pointing
bandwidth (a few Hz, far below the vibration tones), the suspension mode keeps its
frequency and gets ``damping_ratio``. The low-pass on the forces keeps the pointing law out
of the vibration band. The integral carries the payload's weight.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy import signal

from hexapod_vibration.core.control.filters import SosFilterBank
from hexapod_vibration.core.model.geometry import CubicHexapodGeometry
from hexapod_vibration.core.model.kernel_choice import kernels_name
from hexapod_vibration.core.model.sensors import pose_from_gaps

MAX_TILT_RAD = np.deg2rad(2.5)
MAX_TWIST_RAD = np.deg2rad(10.0)
MAX_TRANSLATION_M = 1.0e-3
# Rate feedback is capped at D/m = 2 pi * 3 Hz per axis: beyond that the 1 ms loop delay
# and the output low-pass eat its phase margin (the stiff vertical axis would otherwise
# ask for D/m ~ 17 Hz).
MAX_RATE_GAIN_HZ = 3.0


@dataclass(frozen=True)
class PointingGains:
    """Design of the pointing loop.

    bandwidth_hz: the integral pole (Hz), a few Hz, well below the vibration tones.
    damping_ratio: damping ratio given to each axis' suspension mode (-).
    output_lowpass_hz: corner of the 2nd-order Butterworth on the strut forces (Hz).
    force_limit_n: the output strut forces are saturated at this, and the integral held
        while its own strut forces would exceed it (N).
    """

    bandwidth_hz: float = 1.5
    damping_ratio: float = 0.7
    output_lowpass_hz: float = 15.0
    force_limit_n: float = 70.0

    def __post_init__(self) -> None:
        """Validate ranges (positive, finite)."""
        for name in ("bandwidth_hz", "output_lowpass_hz", "force_limit_n"):
            value = getattr(self, name)
            if not np.isfinite(value) or value <= 0.0:
                raise ValueError(f"{name} must be > 0, got {value!r}")
        if not np.isfinite(self.damping_ratio) or not 0.0 < self.damping_ratio <= 2.0:
            raise ValueError(f"damping_ratio must be in (0, 2], got {self.damping_ratio!r}")


def validate_target_pose(pose: np.ndarray, geometry: CubicHexapodGeometry,
                         stroke_limit_m: float) -> np.ndarray:
    """Check a commanded pose ``[x, y, z, rx, ry, rz]`` (m, rad); raise ValueError if out of range.

    Tilt (norm of rx, ry) within 2.5 deg, twist within 10 deg, translations within 1 mm, and
    the exact strokes the pose needs within 95 % of the actuator stroke.
    """
    pose = np.asarray(pose, float)
    if pose.shape != (6,) or not np.all(np.isfinite(pose)):
        raise ValueError(f"target pose must be 6 finite values, got {pose!r}")
    tilt = float(np.hypot(pose[3], pose[4]))
    if tilt > MAX_TILT_RAD + 1e-12:
        raise ValueError(f"tilt {np.rad2deg(tilt):.3f} deg exceeds the +-2.5 deg range")
    if abs(pose[5]) > MAX_TWIST_RAD + 1e-12:
        raise ValueError(f"twist {np.rad2deg(pose[5]):.3f} deg exceeds the +-10 deg range")
    if np.max(np.abs(pose[:3])) > MAX_TRANSLATION_M + 1e-12:
        raise ValueError(f"translation {pose[:3]} m exceeds +-{MAX_TRANSLATION_M} m")
    stroke = float(np.max(np.abs(geometry.stroke_for_pose(pose))))
    if stroke > 0.95 * stroke_limit_m:
        raise ValueError(f"pose needs {stroke * 1e3:.2f} mm of stroke, more than 95 % of "
                         f"the {stroke_limit_m * 1e3:.1f} mm available")
    return pose


class PointingController:
    """Cartesian PI + damping pointing law on the eddy-sensor pose (see module docstring).

    Per sample the linear part is one product of the law matrix (see :meth:`_law_matrix`)
    with the stacked inputs [gaps, gap change since the last sample, target, integral].
    Where the output low-pass is stepped by the compiled kernels, so is the whole sample
    (:func:`~hexapod_vibration.core.control.compiled_law.pointing_step`, the same numbers).
    """

    def __init__(self, geometry: CubicHexapodGeometry, sensing_matrix: np.ndarray,
                 strut_stiffness_n_per_m: float, top_mass_matrix: np.ndarray,
                 sample_rate_hz: float, gains: PointingGains | None = None) -> None:
        """Derive the Cartesian gains from the platform's stiffness (N/m) and mass matrix."""
        self.geometry = geometry
        self.sensing_matrix = np.asarray(sensing_matrix, float)
        self.dt_s = 1.0 / sample_rate_hz
        self.sample_rate_hz = sample_rate_hz
        self._jac_t = geometry.top_jacobian.T
        self.stiffness = strut_stiffness_n_per_m * geometry.top_jacobian.T @ geometry.top_jacobian
        self._mass = np.asarray(top_mass_matrix, float)
        self._pose_from_gaps = np.linalg.inv(self.sensing_matrix)
        self.target = np.zeros(6)
        # Per-sample buffers: the law's stacked inputs and its four outputs, as views of 6.
        self._inputs = np.zeros(4 * 6)
        self._gaps, self._gap_step, self._target_in, self._integral = np.split(self._inputs, 4)
        self._terms = np.zeros(4 * 6)
        (self._candidate, self._candidate_force, self._force,
         self._held_force) = np.split(self._terms, 4)
        self._new_gaps = np.zeros(6)        # the compiled step's input (m)
        self.set_gains(gains or PointingGains())

    def set_gains(self, gains: PointingGains) -> None:
        """Apply new gains; integral and filter states are kept (bumpless)."""
        k, m = np.diag(self.stiffness), np.diag(self._mass)
        w_c = 2.0 * np.pi * gains.bandwidth_hz
        w_n = np.maximum(np.sqrt(k / m), 2.0 * w_c)
        zeta = gains.damping_ratio
        self.gains = gains
        self._k_int = np.diag(m * w_c * w_n**2)
        self._k_p = np.diag(np.maximum(m * (w_n**2 + 2.0 * zeta * w_n * w_c) - k, 0.0))
        damping = np.minimum(m * (2.0 * zeta * w_n + w_c), m * 2.0 * np.pi * MAX_RATE_GAIN_HZ)
        self._damping = np.diag(damping)
        # Statics J^-T folded into each gain: Cartesian gains -> strut forces.
        jac_inv_t = np.linalg.inv(self._jac_t)
        self._law = self._law_matrix(jac_inv_t @ self._k_p, jac_inv_t @ self._k_int,
                                     jac_inv_t @ self._damping)
        previous = getattr(self, "_lowpass", None)
        self._lowpass = SosFilterBank.butter_lowpass(2, gains.output_lowpass_hz,
                                                     self.sample_rate_hz, 6)
        if previous is None:
            self.reset()
        else:
            self._lowpass.reset(self._last_force)

    def _law_matrix(self, f_p: np.ndarray, f_i: np.ndarray, f_d: np.ndarray) -> np.ndarray:
        """The law as one (24, 24) matrix on the stacked inputs, 6 values each.

        Inputs: gaps (m), gap change since the last sample (m), target (m, rad), integral
        (m s, rad s). With pose = S^-1 gaps, e = target - pose, rate = S^-1 (gap change) / dt
        and the candidate integral c = integral + e dt, the outputs are: c (m s, rad s); its
        strut forces F_i c (N); the strut forces F_p e - F_d rate + F_i c (N); and the same
        with the integral held, F_p e - F_d rate + F_i integral (N), for the anti-windup.
        ``f_p``, ``f_i``, ``f_d`` are the proportional, integral and rate gains mapped to
        strut forces (J^-T K).
        """
        pose, dt = self._pose_from_gaps, self.dt_s
        eye, zero = np.eye(6), np.zeros((6, 6))
        rate_force = -f_d @ pose / dt
        return np.block([
            [-dt * pose, zero, dt * eye, eye],
            [-dt * f_i @ pose, zero, dt * f_i, f_i],
            [-(f_p + dt * f_i) @ pose, rate_force, f_p + dt * f_i, f_i],
            [-f_p @ pose, rate_force, f_p, f_i]])

    def linear_state_space(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """The law as a discrete LTI system (A, B, C, D): gap deviations (m) -> forces (N).

        One step per sample, about a constant target, without the anti-windup (which acts
        only beyond ``force_limit_n``): ``x_{n+1} = A x_n + B g_n``, ``f_n = C x_n + D g_n``,
        state ``[previous gaps (6), integral (6), output low-pass states]``. The same law
        matrix and low-pass as :meth:`step` (tested against it).
        """
        law = self._law
        blk = [[law[6 * r:6 * r + 6, 6 * c:6 * c + 6] for c in range(4)] for r in range(4)]
        (c_gap, c_step, _, c_int), (f_gap, f_step, _, f_int) = blk[0], blk[2]
        lp_a, lp_b, lp_c, lp_d = signal.tf2ss(*signal.sos2tf(self._lowpass.sos))
        eye = np.eye(6)
        n_lp = lp_a.shape[0] * 6
        law_a = np.block([[np.zeros((6, 6)), np.zeros((6, 6))], [-c_step, c_int]])
        law_b = np.vstack([eye, c_gap + c_step])
        law_c, law_d = np.hstack([-f_step, f_int]), f_gap + f_step
        a_lp, b_lp = np.kron(eye, lp_a), np.kron(eye, lp_b)
        c_lp, d_lp = np.kron(eye, lp_c), lp_d[0, 0] * eye
        a = np.block([[law_a, np.zeros((12, n_lp))], [b_lp @ law_c, a_lp]])
        b = np.vstack([law_b, b_lp @ law_d])
        c = np.hstack([d_lp @ law_c, c_lp])
        return a, b, c, d_lp @ law_d

    @property
    def kernels(self) -> str:
        """What steps this law: ``compiled`` (numba kernels) or ``numpy`` (same numbers)."""
        return kernels_name(self._lowpass.compiled)

    def reset(self) -> None:
        """Zero the integral, the rate estimate and the output filter."""
        self._integral[...] = 0.0
        self._primed = False        # the next sample gives a zero rate
        self._last_force = np.zeros(6)
        self._lowpass.reset(0.0)

    def set_target(self, pose: np.ndarray, stroke_limit_m: float = 5.0e-3) -> None:
        """Command a pose ``[x, y, z, rx, ry, rz]`` (m, rad); ValueError if out of range."""
        self.target = validate_target_pose(pose, self.geometry, stroke_limit_m).copy()

    def pose(self, gaps_m: np.ndarray) -> np.ndarray:
        """Relative pose (m, rad) from the six eddy-sensor gaps (m)."""
        return pose_from_gaps(self.sensing_matrix, gaps_m)

    def step(self, gaps_m: np.ndarray) -> np.ndarray:
        """One sample: eddy gaps (m) -> strut forces (N) for the same sample (a new array)."""
        kernels = self._lowpass.compiled
        if kernels is not None:
            return self._compiled_step(kernels, gaps_m)
        if self._primed:
            np.subtract(gaps_m, self._gaps, self._gap_step)
        else:
            self._gap_step[...] = 0.0           # first sample: zero rate
            self._primed = True
        self._gaps[...] = gaps_m
        self._target_in[...] = self.target
        np.matmul(self._law, self._inputs, self._terms)     # see _law_matrix
        if _exceeds(self._candidate_force, self.gains.force_limit_n):
            force = self._held_force            # anti-windup: integral held
        else:
            self._integral[...] = self._candidate
            force = self._force
        force = self._lowpass.step(force)                 # a new array
        limit = self.gains.force_limit_n
        np.minimum(force, limit, out=force)
        self._last_force = np.maximum(force, -limit, out=force)
        return self._last_force

    def _compiled_step(self, kernels, gaps_m: np.ndarray) -> np.ndarray:
        """:meth:`step` in one call of the compiled kernels (the same numbers)."""
        self._new_gaps[...] = gaps_m
        force = np.empty(6)
        kernels.pointing_step(self._law, self._inputs, self._terms, self._new_gaps,
                              self.target, self._primed, self.gains.force_limit_n,
                              self._lowpass.sos, self._lowpass.state, force)
        self._primed = True
        self._last_force = force
        return force


def _exceeds(values: np.ndarray, limit: float) -> bool:
    """``np.abs(values).max() > limit`` (False if any value is NaN), cheaper for a few values."""
    magnitudes = list(map(abs, values.tolist()))
    return max(magnitudes) > limit and not math.isnan(sum(magnitudes))
