"""Sensors of the PPH and the DC-blocking filter of the control path.

- :class:`AccelerometerBank`: six in-line accelerometers measuring the axial specific force
  of each strut's moving part (gravity included, m/s^2), through an anti-aliasing
  Butterworth filter running at the internal rate, white noise, +-2 g clipping and 16-bit
  quantisation, sampled at 1 kHz.
- :class:`EddySensorArray`: six eddy-current gap sensors in three pairs (one axial, one
  tangential) on the top plate, targets on the bottom plate; gaps (m) with noise, and the
  pose recovered from them.
"""

from __future__ import annotations

import numpy as np
from scipy import signal

from hexapod_vibration.core.model.config import AccelerometerConfig, EddyConfig
from hexapod_vibration.core.model.geometry import point_jacobian
from hexapod_vibration.core.model.kernel_choice import compiled_kernels

G0_M_S2 = 9.80665


class AccelerometerBank:
    """Anti-alias filter + noise + clipping + quantisation for ``channels`` accelerometers.

    The Butterworth anti-aliasing filter runs at the internal rate; since it is linear, the
    internal steps of one sample are applied with one lifted state-space product.
    """

    def __init__(self, config: AccelerometerConfig, internal_rate_hz: float,
                 sample_rate_hz: float, channels: int = 6, seed: int = 0) -> None:
        """Design the anti-aliasing filter at the internal rate (Hz)."""
        self.config = config
        self.internal_rate_hz = internal_rate_hz
        self.substeps = int(round(internal_rate_hz / sample_rate_hz))
        b, a = signal.butter(config.antialias_order, config.antialias_cutoff_hz,
                             fs=internal_rate_hz)
        self._ba = (b, a)
        self._lift_filter(*signal.tf2ss(b, a))
        self._x = np.zeros((self._state_update.shape[0], channels))
        self.range_m_s2 = config.range_g * G0_M_S2
        self.lsb_m_s2 = 2.0 * self.range_m_s2 / 2 ** config.bits
        self.noise_rms_m_s2 = (config.noise_density_g_per_sqrt_hz * G0_M_S2
                               * np.sqrt(sample_rate_hz / 2.0))
        self._rng = np.random.default_rng(seed)
        self.clipped_samples = 0
        # Scratch for sample(): filter output and state update, each as its two products.
        self._out_terms = (np.empty((1, channels)), np.empty((1, channels)))
        self._state_terms = (np.empty(self._x.shape), np.empty(self._x.shape))
        self._clipped = np.empty(channels)
        self._was_clipped = np.empty(channels, bool)
        self._kernels = compiled_kernels()

    def _lift_filter(self, a: np.ndarray, b: np.ndarray, c: np.ndarray, d: np.ndarray) -> None:
        """Matrices mapping (state, inputs of one sample) to (next state, last output)."""
        n, ns = a.shape[0], self.substeps
        state = np.eye(n)
        inputs = np.zeros((n, ns))
        for k in range(ns - 1):
            state, inputs = a @ state, a @ inputs
            inputs[:, k] += b[:, 0]
        out_state, out_inputs = c @ state, c @ inputs
        out_inputs[0, ns - 1] += d[0, 0]
        self._out_state, self._out_inputs = out_state, out_inputs
        inputs = a @ inputs
        inputs[:, ns - 1] += b[:, 0]
        self._state_update, self._input_update = a @ state, inputs

    def settle(self, specific_force_m_s2: np.ndarray) -> None:
        """Put the filter in steady state at a constant input (e.g. gravity at rest)."""
        ones = np.ones((self.substeps, specific_force_m_s2.size)) * specific_force_m_s2
        for _ in range(200):
            self._x = self._state_update @ self._x + self._input_update @ ones

    def sample(self, specific_force_m_s2: np.ndarray) -> np.ndarray:
        """Filter one sample's internal steps (substeps, channels) and return the ADC reading.

        Returns the value at the sampling instant (last internal step), in m/s^2.
        """
        if self._kernels is not None:
            noise = self._rng.normal(0.0, self.noise_rms_m_s2, self._x.shape[1])
            reading = np.empty(self._x.shape[1])
            self.clipped_samples += self._kernels.accelerometer_reading(
                self._out_state, self._out_inputs, self._state_update, self._input_update,
                self._x, specific_force_m_s2, noise, self.range_m_s2, self.lsb_m_s2, reading)
            return reading
        filtered = self._filter(specific_force_m_s2)
        value = filtered + self._rng.normal(0.0, self.noise_rms_m_s2, filtered.shape[0])
        clipped = np.maximum(value, -self.range_m_s2, out=self._clipped)
        np.minimum(clipped, self.range_m_s2 - self.lsb_m_s2, out=clipped)
        if np.count_nonzero(np.not_equal(clipped, value, out=self._was_clipped)):
            self.clipped_samples += 1
        return np.rint(np.divide(clipped, self.lsb_m_s2, out=clipped), out=clipped) * self.lsb_m_s2

    def _filter(self, specific_force_m_s2: np.ndarray) -> np.ndarray:
        """Advance the anti-aliasing filter by one sample; its output (m/s^2) at the end.

        The same products and sums as ``C x + D u`` and ``A x + B u`` written out, into
        preallocated buffers; the returned row is a buffer, valid until the next call.
        """
        out_now, out_in = self._out_terms
        x_now, x_in = self._state_terms
        np.dot(self._out_state, self._x, out=out_now)
        np.dot(self._out_inputs, specific_force_m_s2, out=out_in)
        np.dot(self._state_update, self._x, out=x_now)
        np.dot(self._input_update, specific_force_m_s2, out=x_in)
        np.add(x_now, x_in, out=self._x)
        return np.add(out_now, out_in, out=out_now)[0]

    @property
    def antialias_ba(self) -> tuple[np.ndarray, np.ndarray]:
        """(b, a) of the anti-aliasing filter at the internal rate."""
        return self._ba

    def antialias_response(self, frequencies_hz: np.ndarray) -> np.ndarray:
        """Complex frequency response of the anti-aliasing filter."""
        _, h = signal.freqz(*self._ba, worN=np.asarray(frequencies_hz), fs=self.internal_rate_hz)
        return h


def eddy_sensor_layout(radius_m: float, height_m: float) -> tuple[np.ndarray, np.ndarray]:
    """Points (6, 3) and measuring directions (6, 3) of the three sensor pairs.

    Pairs at 90, 210 and 330 deg: the first of each pair measures along z, the second
    along the tangent.
    """
    angles = np.deg2rad([90.0, 210.0, 330.0])
    points, directions = [], []
    for a in angles:
        p = np.array([radius_m * np.cos(a), radius_m * np.sin(a), height_m])
        points += [p, p]
        directions += [np.array([0.0, 0.0, 1.0]), np.array([-np.sin(a), np.cos(a), 0.0])]
    return np.array(points), np.array(directions)


class EddySensorArray:
    """Six gap sensors measuring the top plate relative to the bottom plate (m)."""

    def __init__(self, config: EddyConfig, height_m: float, seed: int = 0) -> None:
        """Lay out the sensors at ``config.radius_m`` on the plane ``height_m`` (m)."""
        self.config = config
        points, directions = eddy_sensor_layout(config.radius_m, height_m)
        jac = point_jacobian(points)
        self.sensing_matrix = np.einsum("kd,kdj->kj", directions, jac)
        self._rng = np.random.default_rng(seed)

    def gaps(self, relative_pose: np.ndarray) -> np.ndarray:
        """Gap changes (m) for a top-minus-bottom pose ``[x, y, z, rx, ry, rz]``, with noise."""
        noise = self._rng.normal(0.0, self.config.noise_rms_m, 6)
        return np.add(self.sensing_matrix.dot(relative_pose), noise, out=noise)

    def pose(self, gaps_m: np.ndarray) -> np.ndarray:
        """Relative pose from gap changes: (6,) or (N, 6)."""
        return pose_from_gaps(self.sensing_matrix, gaps_m)


def pose_from_gaps(sensing_matrix: np.ndarray, gaps_m: np.ndarray) -> np.ndarray:
    """Solve the 6x6 sensing equations for the pose (m, rad); accepts (6,) or (N, 6)."""
    return np.linalg.solve(sensing_matrix, np.asarray(gaps_m, float).T).T
