"""A whole 1 kHz sample of the plant in one matrix product, and whether it stayed in regime.

While no joint changes contact side and no stop is touched, the plant is linear over the
sample's internal steps, so its state at the end, the specific force at each internal step,
the nonlinear outputs (strokes, stroke rates, joint deflections) at the start of each next
step and the top plate's acceleration are one product of a lifted matrix with
``[state; held input; shaker force per internal step]``. :class:`LiftedSample` holds that
matrix, its input and output buffers (the output's rows as named views) and the test of
which internal steps stayed in the regime; :class:`~hexapod_vibration.core.model.plant.
PPHPlant` fills the input, decides, and steps one by one where the regime broke.
"""

from __future__ import annotations

from types import ModuleType

import numpy as np


def lifted_matrix(step_matrix: np.ndarray, nl_out: np.ndarray, substeps: int,
                  shaker_column: int) -> np.ndarray:
    """Map ``[x0; u_held; shaker(substeps)]`` to a whole sample's outputs at once.

    ``step_matrix`` maps ``[x; u]`` to ``[next state; strut specific force; top accel; ...]``
    over one internal step, ``nl_out`` the state to the 18 nonlinear outputs;
    ``shaker_column`` is the shaker force's place in ``u``. Rows: final state, specific force
    per substep (substeps x 6), nonlinear outputs at the start of substeps 1..substeps
    (substeps x 18, the last one is the next sample's start), top-plate acceleration at the
    end (6).
    """
    n = nl_out.shape[1]
    m = step_matrix.shape[1] - n
    width = n + m + substeps
    x = np.zeros((n, width))
    x[:, :n] = np.eye(n)
    rows_acc, rows_nl = [], []
    accel_rows = step_matrix[n:n + 12]        # [strut accel; top accel] of [x; u]
    for k in range(substeps):
        u = np.zeros((m, width))
        u[:, n:n + m] = np.eye(m)
        u[shaker_column, n + m + k] = 1.0
        x_next = step_matrix[:n] @ np.vstack([x, u])
        acc = accel_rows @ np.vstack([x_next, u])    # acceleration at the substep's end
        rows_acc.append(acc[:6])
        rows_nl.append(nl_out @ x_next)
        x = x_next
    return np.vstack([x, *rows_acc, *rows_nl, acc[6:12]])


class LiftedSample:
    """The lifted product of one sample, its buffers, and its regime test.

    Args:
        step_matrix, nl_out, substeps, shaker_column: as for :func:`lifted_matrix`.
        strut: ``[stroke_limit_m, force_constant_linear_per_stroke,
            force_constant_quadratic_per_stroke, half_play_m]`` (the compiled kernels' layout).
        kernels: the compiled kernels (``kernel_choice.compiled_kernels``) or None (NumPy).
    """

    def __init__(self, step_matrix: np.ndarray, nl_out: np.ndarray, substeps: int,
                 shaker_column: int, strut: np.ndarray, kernels: ModuleType | None) -> None:
        """Build the matrix and bind the buffers' views."""
        n = nl_out.shape[1]
        self.substeps = substeps
        self.matrix = lifted_matrix(step_matrix, nl_out, substeps, shaker_column)
        self.inputs = np.zeros(self.matrix.shape[1])
        """``[state; held input u; shaker force per internal step (N)]``: the caller fills u."""
        self.shaker_in = self.inputs[self.inputs.size - substeps:]
        self.contact_side = np.zeros(6)
        """Side (+-1) each joint is held against while in the regime (with free-play)."""
        out = np.zeros(self.matrix.shape[0])
        nl_rows = out[n + 6 * substeps:n + 24 * substeps].reshape(substeps, 18)
        self.outputs = out
        self.out_state = out[:n]
        self.out_specific_force = out[n:n + 6 * substeps].reshape(substeps, 6)
        self.out_next_nl = nl_rows[-1]
        self.out_top_acc = out[n + 24 * substeps:]
        # The strokes and joint deflections (substeps x 6, m) at the start of internal steps
        # 1..substeps, the last one being the start of the next sample.
        self._strokes, self._joints = nl_rows[:, 0:6], nl_rows[:, 12:18]
        self._strut = strut
        self._stroke_limit_m, self._half_play_m = float(strut[0]), float(strut[3])
        self._scratch = np.empty((substeps, 6))
        self._kernels = kernels

    def rows_in_regime(self, state: np.ndarray, force_n: np.ndarray) -> int:
        """The product from ``state`` with the held ``force_n`` (N); leading steps in regime.

        The count is exact from the compiled kernel; the NumPy path tells only whether all
        ``substeps``, all but the last (``substeps - 1``) or fewer (0) do, all that
        ``PPHPlant._lifted_step`` asks.
        """
        ns = self.substeps
        if self._kernels is not None:
            return self._kernels.lifted_rows(self.matrix, self.inputs, self.outputs, state,
                                             force_n, self._strut, self.contact_side, ns)
        v, n = self.inputs, state.size
        v[:n] = state
        v[n:n + 6] = force_n
        np.dot(self.matrix, v, out=self.outputs)
        if self._leading_rows_hold(ns):
            return ns
        return ns - 1 if self._leading_rows_hold(ns - 1) else 0

    def _leading_rows_hold(self, rows: int) -> bool:
        """True if the first ``rows`` internal steps of the output stay in the regime.

        In the regime no stroke exceeds ``stroke_limit_m`` (no stop is touched) and no joint
        deflection comes within half the free-play of its contact side.
        """
        scratch = self._scratch[:rows]
        if np.abs(self._strokes[:rows], out=scratch).max() > self._stroke_limit_m:
            return False
        if self._half_play_m == 0.0:
            return True
        np.multiply(self._joints[:rows], self.contact_side, out=scratch)
        return bool(scratch.min() > self._half_play_m)
