"""Dynamics of the simulated Precision Pointing Hexapod.

Bodies and coordinates (18 degrees of freedom, displacements from the nominal pose):

- ``q_t`` (6): top plate + payload, pose ``[x, y, z, rx, ry, rz]`` of the cube centre.
- ``q_b`` (6): bottom plate, same reference point; it sits on soft isolation mounts on the
  floating (inertial) table and carries the shaker.
- ``z`` (6): axial displacement of each strut's moving part (voice coil, shaft and the
  in-line accelerometer).

Each strut: the voice coil pushes its moving part against the base joint (force constant
varying with stroke), an axial suspension spring and damper act across the stroke, hard
stops act beyond +-5 mm, and the moving part drives the top plate through the ball joints,
which have free-play (a dead zone of ``joint_free_play_m``) and contact stiffness.

The linear part (masses, springs, dampers, mounts, gravity) is integrated exactly with a
zero-order-hold discretisation at the internal rate (10 kHz); the nonlinear strut forces
(force constant, hard stops, free-play correction) are evaluated at every internal step and
held over it. Rigid-body kinematics are linearised about the nominal pose.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.linalg import expm

from hexapod_vibration.core.model.config import ModelConfig, RigidBodyConfig, StrutConfig
from hexapod_vibration.core.model.geometry import point_jacobian, skew
from hexapod_vibration.core.model.kernel_choice import compiled_kernels, kernels_name
from hexapod_vibration.core.model.lifted_sample import LiftedSample
from hexapod_vibration.core.model.sensors import AccelerometerBank, EddySensorArray
from hexapod_vibration.core.model.shaker import Shaker

N_DOF = 18
N_STATE = 2 * N_DOF
# Input vector: strut forces (6), free-play correction (6), shaker force (1), gravity (1).
IN_STRUT, IN_JOINT, IN_SHAKER, IN_GRAVITY = slice(0, 6), slice(6, 12), 12, 13
N_INPUT = 14


@dataclass
class PlantSample:
    """What one 1 kHz sample of the plant produces.

    accel_m_s2: the six accelerometer readings (raw, gravity included).
    eddy_m: the six eddy-sensor gap changes.
    applied_force_n: the force each voice coil produced (command times force constant).
    top_accel_true: true top-plate acceleration ``[m/s^2 x3, rad/s^2 x3]`` (no sensor).
    relative_pose_true: true top-minus-bottom pose (m, rad).
    stroke_m: strut strokes.
    """

    accel_m_s2: np.ndarray
    eddy_m: np.ndarray
    applied_force_n: np.ndarray
    top_accel_true: np.ndarray
    relative_pose_true: np.ndarray
    stroke_m: np.ndarray


def rigid_body_mass_matrix(body: RigidBodyConfig) -> np.ndarray:
    """6x6 mass matrix about the reference point for a body with an offset COM."""
    r = skew(np.asarray(body.com_offset_m))
    m = body.mass_kg
    mass = np.zeros((6, 6))
    mass[:3, :3] = m * np.eye(3)
    mass[:3, 3:] = -m * r
    mass[3:, :3] = m * r
    mass[3:, 3:] = np.diag(body.inertia_kg_m2) - m * r @ r
    return mass


def saturate_commands(notch_n: np.ndarray, pointing_n: np.ndarray,
                      strut: StrutConfig) -> np.ndarray:
    """Actuator limits: vibration command within the dynamic rating, sum within the static.

    ``np.minimum(np.maximum(...))`` is ``np.clip`` value for value (NaN included) at a third
    of its per-call cost (``np.clip`` goes through two Python wrappers): this runs every
    sample in the driver and the core loop.
    """
    dynamic = np.maximum(notch_n, -strut.force_limit_dynamic_n)
    np.minimum(dynamic, strut.force_limit_dynamic_n, out=dynamic)
    total = np.add(dynamic, pointing_n, out=dynamic)
    np.maximum(total, -strut.force_limit_static_n, out=total)
    return np.minimum(total, strut.force_limit_static_n, out=total)


class LinearHexapodModel:
    """Mass, stiffness, damping and input matrices of the 18-DOF model (SI units)."""

    def __init__(self, config: ModelConfig) -> None:
        """Assemble the matrices from the model configuration."""
        geo, st = config.geometry, config.strut
        self.config = config
        self.stroke_map = np.hstack([np.zeros((6, 6)), -geo.base_jacobian, np.eye(6)])
        self.joint_map = np.hstack([-geo.top_jacobian, np.zeros((6, 6)), np.eye(6)])
        self.mass = np.zeros((N_DOF, N_DOF))
        self.mass[:6, :6] = rigid_body_mass_matrix(config.top_plate)
        self.mass[6:12, 6:12] = rigid_body_mass_matrix(config.bottom_plate)
        self.mass[12:, 12:] = st.moving_mass_kg * np.eye(6)
        mount_k, mount_c = self._mount_matrices()
        s, d = self.stroke_map, self.joint_map
        self.stiffness = st.suspension_stiffness_n_per_m * s.T @ s
        self.stiffness += st.joint_stiffness_n_per_m * d.T @ d
        self.stiffness[6:12, 6:12] += mount_k
        self.damping = st.suspension_damping_n_s_per_m * s.T @ s
        self.damping += st.joint_damping_n_s_per_m * d.T @ d
        self.damping[6:12, 6:12] += mount_c
        self.input_map = self._input_map()

    def _mount_matrices(self) -> tuple[np.ndarray, np.ndarray]:
        mc = self.config.mounts
        angles = np.deg2rad(45.0 + 360.0 / mc.count * np.arange(mc.count))
        points = np.stack([mc.radius_m * np.cos(angles), mc.radius_m * np.sin(angles),
                           np.full(mc.count, mc.height_m)], axis=1)
        jac = point_jacobian(points)
        k = np.diag([mc.lateral_stiffness_n_per_m] * 2 + [mc.vertical_stiffness_n_per_m])
        c = np.diag([mc.lateral_damping_n_s_per_m] * 2 + [mc.vertical_damping_n_s_per_m])
        return (np.einsum("kai,ab,kbj->ij", jac, k, jac),
                np.einsum("kai,ab,kbj->ij", jac, c, jac))

    def _input_map(self) -> np.ndarray:
        cfg = self.config
        g = cfg.simulation.gravity_m_s2
        bq = np.zeros((N_DOF, N_INPUT))
        bq[:, IN_STRUT] = self.stroke_map.T
        bq[:, IN_JOINT] = self.joint_map.T
        ez = np.array([0.0, 0.0, 1.0])
        shaker_point = np.asarray(cfg.shaker.position_m)
        shaker_rows = slice(0, 6) if cfg.shaker.mounted_on == "top_plate" else slice(6, 12)
        bq[shaker_rows, IN_SHAKER] = np.concatenate([ez, np.cross(shaker_point, ez)])
        for rows, body in ((slice(0, 6), cfg.top_plate), (slice(6, 12), cfg.bottom_plate)):
            weight = -body.mass_kg * g * ez
            bq[rows, IN_GRAVITY] = np.concatenate([weight, np.cross(body.com_offset_m, weight)])
        unit = cfg.geometry.unit_vectors
        bq[12:, IN_GRAVITY] = -cfg.strut.moving_mass_kg * g * unit[:, 2]
        # The moving parts only move axially: the lateral part of their weight goes through
        # the strut's guide into its base, i.e. onto the bottom plate.
        lateral = -cfg.strut.moving_mass_kg * g * (ez - unit[:, 2:3] * unit)
        base = cfg.geometry.base_joints_m
        bq[6:12, IN_GRAVITY] += np.concatenate([lateral.sum(0), np.cross(base, lateral).sum(0)])
        return bq

    def state_space(self) -> tuple[np.ndarray, np.ndarray]:
        """Continuous ``x_dot = A x + B u`` with ``x = [q, q_dot]``."""
        minv = np.linalg.inv(self.mass)
        a = np.zeros((N_STATE, N_STATE))
        a[:N_DOF, N_DOF:] = np.eye(N_DOF)
        a[N_DOF:, :N_DOF] = -minv @ self.stiffness
        a[N_DOF:, N_DOF:] = -minv @ self.damping
        b = np.zeros((N_STATE, N_INPUT))
        b[N_DOF:] = minv @ self.input_map
        return a, b

    def modal_frequencies_hz(self) -> np.ndarray:
        """Undamped natural frequencies (Hz), ascending, from ``K v = w^2 M v``."""
        from scipy.linalg import eigh

        w2 = eigh(self.stiffness, self.mass, eigvals_only=True)
        return np.sqrt(np.clip(w2, 0.0, None)) / (2.0 * np.pi)


def discretize(a: np.ndarray, b: np.ndarray, dt_s: float) -> tuple[np.ndarray, np.ndarray]:
    """Exact zero-order-hold discretisation of ``(A, B)`` over ``dt_s``."""
    n, m = b.shape
    block = np.zeros((n + m, n + m))
    block[:n, :n], block[:n, n:] = a, b
    phi = expm(block * dt_s)
    return phi[:n, :n], phi[:n, n:]


class PPHPlant:
    """The simulated hexapod: mechanics at the internal rate, sensors sampled at 1 kHz."""

    def __init__(self, config: ModelConfig, shaker: Shaker | None = None, seed: int = 0) -> None:
        """Build the model, start at static equilibrium under gravity, sensors settled."""
        self.config = config
        self.model = LinearHexapodModel(config)
        sim, st = config.simulation, config.strut
        self.substeps = sim.substeps
        self.dt_internal_s = 1.0 / sim.internal_rate_hz
        self.dt_sample_s = 1.0 / sim.sample_rate_hz
        a, b = self.model.state_space()
        ad, bd = discretize(a, b, self.dt_internal_s)
        self._step_matrix = self._build_step_matrix(a, b, ad, bd)
        self._half_play = 0.5 * st.joint_free_play_m
        self._strut = st
        rng = np.random.default_rng(seed)
        self.shaker = shaker or Shaker(force_limit_n=config.shaker.force_limit_n,
                                       seed=int(rng.integers(2**31)))
        self.accelerometers = AccelerometerBank(config.accelerometer, sim.internal_rate_hz,
                                                sim.sample_rate_hz, seed=int(rng.integers(2**31)))
        height = float(config.geometry.top_joints_m[0, 2])
        self.eddy = EddySensorArray(config.eddy, height, seed=int(rng.integers(2**31)))
        self.sample_index = 0
        self._xu = np.zeros(N_STATE + N_INPUT)
        self._xu[N_STATE + IN_GRAVITY] = 1.0
        self._acc = np.zeros((self.substeps, 6))
        self._top_acc = np.zeros(6)
        self._ratio, self._gain = np.empty(6), np.empty(6)
        self._kernels = compiled_kernels()
        self._strut_constants = np.array([st.stroke_limit_m, st.force_constant_linear_per_stroke,
                                          st.force_constant_quadratic_per_stroke,
                                          self._half_play])
        self._lifted = LiftedSample(self._step_matrix, self._nl_out, self.substeps, IN_SHAKER,
                                    self._strut_constants, self._kernels)
        self._lifted.inputs[N_STATE + IN_GRAVITY] = 1.0
        self._state_now = self._xu[:N_STATE]
        self._specific_force = self._acc
        self._start_in_regime = False
        self.fallback_samples = 0
        self.reset_to_equilibrium()

    def _build_step_matrix(self, a: np.ndarray, b: np.ndarray, ad: np.ndarray,
                           bd: np.ndarray) -> np.ndarray:
        """One matrix giving [next state; strut specific force; top accel; nl outputs]."""
        g = self.config.simulation.gravity_m_s2
        accel = np.hstack([a[N_DOF:], b[N_DOF:]])            # q_ddot from [x; u]
        strut_accel = accel[12:18].copy()
        strut_accel[:, N_STATE + IN_GRAVITY] += g * self.config.geometry.unit_vectors[:, 2]
        nl_out = np.zeros((18, N_STATE))
        nl_out[0:6, :N_DOF] = self.model.stroke_map
        nl_out[6:12, N_DOF:] = self.model.stroke_map
        nl_out[12:18, :N_DOF] = self.model.joint_map
        next_state = np.hstack([ad, bd])
        self._nl_out = nl_out
        return np.vstack([next_state, strut_accel, accel[0:6], nl_out @ next_state])

    @property
    def kernels(self) -> str:
        """What steps this plant: ``compiled`` (numba kernels) or ``numpy`` (same numbers)."""
        return kernels_name(self._kernels)

    @property
    def state(self) -> np.ndarray:
        """Current state ``[q (18), q_dot (18)]`` (copy)."""
        return self._xu[:N_STATE].copy()

    def set_state(self, state: np.ndarray) -> None:
        """Overwrite the mechanical state (for tests and initial conditions)."""
        self._xu[:N_STATE] = state
        self._refresh_carried_over()

    def _refresh_carried_over(self) -> None:
        """Recompute what :meth:`step` carries from one sample to the next from the state.

        ``_nl`` holds the strokes (force constant, hard stops), stroke rates and joint
        deflections at the start of the next sample; ``_start_in_regime`` says whether the
        start-of-sample regime test (and so the contact sides and the held free-play
        correction) may be skipped. Both describe the state, so they follow it when it is
        overwritten.
        """
        self._nl = self._nl_out @ self._xu[:N_STATE]
        self._start_in_regime = False

    def reset_to_equilibrium(self) -> None:
        """Static equilibrium under gravity with no command, sensors settled on it."""
        k, bq = self.model.stiffness, self.model.input_map
        q = np.linalg.solve(k, bq[:, IN_GRAVITY])
        for _ in range(50):   # free-play contact: fixed point on the bounded correction
            joint = self.model.joint_map @ q
            corr = self._strut.joint_stiffness_n_per_m * np.clip(joint, -self._half_play,
                                                                 self._half_play)
            q = np.linalg.solve(k, bq[:, IN_GRAVITY] + bq[:, IN_JOINT] @ corr)
        self._xu[:N_STATE] = 0.0
        self._xu[:N_DOF] = q
        self._refresh_carried_over()
        g = self.config.simulation.gravity_m_s2
        self.accelerometers.settle(g * self.config.geometry.unit_vectors[:, 2])

    def _held_actuator_force(self, command_n: np.ndarray) -> np.ndarray:
        """Voice-coil force (N): command times the force constant at this sample's stroke."""
        if self._kernels is not None:
            force = np.empty(6)
            self._kernels.held_force(self._nl, command_n, self._strut_constants, force)
            return force
        st, ratio, gain = self._strut, self._ratio, self._gain
        np.divide(self._nl[0:6], st.stroke_limit_m, out=ratio)
        np.multiply(st.force_constant_quadratic_per_stroke, ratio, out=gain)
        np.subtract(st.force_constant_linear_per_stroke, gain, out=gain)
        np.multiply(ratio, gain, out=gain)
        return command_n * np.add(1.0, gain, out=gain)

    def _stop_and_play(self, nl: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Hard-stop force and free-play correction (N) from nonlinear outputs."""
        st = self._strut
        stroke, rate, joint = nl[0:6], nl[6:12], nl[12:18]
        over = stroke - np.clip(stroke, -st.stroke_limit_m, st.stroke_limit_m)
        stop = -st.hard_stop_stiffness_n_per_m * over
        stop -= st.hard_stop_damping_n_s_per_m * rate * (over != 0.0)
        play = st.joint_stiffness_n_per_m * np.clip(joint, -self._half_play, self._half_play)
        return stop, play

    def _enter_regime(self) -> bool:
        """Start-of-sample test of the lifted step, and its held free-play correction.

        True if no hard-stop force acts and (with free-play) every joint is deflected
        beyond half the clearance: it is then held against one side
        (``LiftedSample.contact_side``, +-1) and its correction is the constant
        ``joint_stiffness * half_play * side`` (N).
        """
        stop, play = self._stop_and_play(self._nl)
        if stop.any():
            return False
        if self._half_play != 0.0:
            joint = self._nl[12:18]
            side = np.sign(joint)
            if not (joint * side).min() > self._half_play:
                return False
            self._lifted.contact_side[:] = side
        self._lifted.inputs[N_STATE + 6:N_STATE + 12] = play
        self._start_in_regime = True
        return True

    def step(self, force_command_n: np.ndarray) -> PlantSample:
        """Advance one sample (1 ms) holding ``force_command_n`` (N, already saturated).

        The voice-coil force constant is evaluated at the stroke at the start of the
        sample and held for it; free-play and hard stops act at every internal step.
        """
        t0 = self.sample_index * self.dt_sample_s
        shaker = self.shaker.force_into(t0, self.dt_internal_s, self._lifted.shaker_in)
        actuator = self._held_actuator_force(np.ascontiguousarray(force_command_n, float))
        if not self._lifted_step(actuator, shaker):
            self._substep_loop(actuator, shaker)
            self.fallback_samples += 1
        self.sample_index += 1
        q = self._xu[:N_DOF]
        relative = q[:6] - q[6:12]
        return PlantSample(
            accel_m_s2=self.accelerometers.sample(self._specific_force),
            eddy_m=self.eddy.gaps(relative),
            applied_force_n=actuator,
            top_accel_true=self._top_acc.copy(),
            relative_pose_true=relative,
            stroke_m=self._nl[0:6].copy(),
        )

    def _lifted_step(self, actuator: np.ndarray, shaker: np.ndarray) -> bool:
        """Whole sample in one product, valid when the contact regime does not change.

        ``shaker`` is the force (N) per internal step; :meth:`step` has the shaker write
        it straight into the product's input (``LiftedSample.shaker_in``). When all internal steps,
        including the start of the next sample, stay in the regime, the next sample
        skips the start test (its outcome is then known: no stop force, same sides).
        """
        if not (self._start_in_regime or self._enter_regime()):
            return False
        lifted = self._lifted
        if shaker is not lifted.shaker_in:
            lifted.shaker_in[:] = shaker
        rows = lifted.rows_in_regime(self._state_now, actuator)
        if rows < self.substeps:
            self._start_in_regime = False
            if rows < self.substeps - 1:
                return False
        self._xu[:N_STATE] = lifted.out_state
        self._specific_force = lifted.out_specific_force
        self._nl = lifted.out_next_nl.copy()
        self._top_acc = lifted.out_top_acc
        return True

    def _substep_loop(self, actuator: np.ndarray, shaker: np.ndarray) -> None:
        """Internal steps one by one (free-play crossing or hard-stop contact)."""
        self._start_in_regime = False
        self._specific_force = self._acc
        xu, u = self._xu, self._xu[N_STATE:]
        for k in range(self.substeps):
            stop, play = self._stop_and_play(self._nl)
            u[IN_STRUT], u[IN_JOINT], u[IN_SHAKER] = actuator + stop, play, shaker[k]
            out = self._step_matrix @ xu
            xu[:N_STATE] = out[:N_STATE]
            u_end = np.concatenate([out[:N_STATE], u])
            acc = self._step_matrix[N_STATE:N_STATE + 12] @ u_end
            self._acc[k] = acc[:6]
            self._top_acc = acc[6:12]
            self._nl = out[N_STATE + 12:]

    def mechanical_energy_j(self) -> float:
        """Kinetic + elastic (springs, mounts, free-play contact, stops) + gravity energy (J)."""
        q, qd = self._xu[:N_DOF], self._xu[N_DOF:N_STATE]
        st, model = self._strut, self.model
        stroke = model.stroke_map @ q
        joint = model.joint_map @ q
        contact = joint - np.clip(joint, -self._half_play, self._half_play)
        over = stroke - np.clip(stroke, -st.stroke_limit_m, st.stroke_limit_m)
        mount_k = model.stiffness[6:12, 6:12] - (
            st.suspension_stiffness_n_per_m * model.stroke_map[:, 6:12].T
            @ model.stroke_map[:, 6:12])
        return float(0.5 * qd @ model.mass @ qd
                     + 0.5 * st.suspension_stiffness_n_per_m * stroke @ stroke
                     + 0.5 * st.joint_stiffness_n_per_m * contact @ contact
                     + 0.5 * st.hard_stop_stiffness_n_per_m * over @ over
                     + 0.5 * q[6:12] @ mount_k @ q[6:12]
                     - model.input_map[:, IN_GRAVITY] @ q)
