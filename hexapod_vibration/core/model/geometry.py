"""Stewart-platform geometry of the Precision Pointing Hexapod in the cubic configuration.

The six struts lie on six edges of a cube whose body diagonal is the platform's z axis
(the edges that touch neither end of that diagonal: a zig-zag of mutually orthogonal
lines). The cube's centre is the reference point of the top plate (the payload's centre of
mass). Joints sit on those lines below the cube, so the lever arms (and the decoupling of
the cubic configuration) depend only on the cube's edge, while the strut length and the
joint radii are free.

Pose vectors are ``[x, y, z, rx, ry, rz]`` (m, m, m, rad, rad, rad): small displacements
of the top plate's reference point and rotations about the platform axes. The dynamic model
uses the Jacobian at the nominal pose (valid for the vibration band and for the pointing
range, see :func:`CubicHexapodGeometry.linearization_error`); :meth:`strut_lengths` is the
exact inverse kinematics for any pose.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.spatial.transform import Rotation


def skew(v: np.ndarray) -> np.ndarray:
    """Return the cross-product matrix ``[v]x`` so that ``skew(v) @ w == cross(v, w)``."""
    x, y, z = v
    return np.array([[0.0, -z, y], [z, 0.0, -x], [-y, x, 0.0]])


def point_jacobian(points_m: np.ndarray) -> np.ndarray:
    """Velocity of body-fixed points per pose rate: shape (N, 3, 6), ``[I, -[r]x]``."""
    points_m = np.atleast_2d(points_m)
    jac = np.zeros((points_m.shape[0], 3, 6))
    jac[:, :, :3] = np.eye(3)
    for k, r in enumerate(points_m):
        jac[k, :, 3:] = -skew(r)
    return jac


def axial_jacobian(points_m: np.ndarray, directions: np.ndarray) -> np.ndarray:
    """Rate of displacement along ``directions`` of body-fixed ``points_m`` per pose rate.

    Row i is ``[u_i, r_i x u_i]``: shape (N, 6). This is the Stewart Jacobian when the
    points are the joints and the directions the strut unit vectors.
    """
    return np.hstack([directions, np.cross(points_m, directions)])


def _cube_strut_lines(cube_edge_m: float) -> tuple[np.ndarray, np.ndarray]:
    """Lower vertex (6, 3) and upward unit vector (6, 3) of each cube edge used as a strut.

    Strut order walks the zig-zag so that neighbours are orthogonal and struts i, i+3
    are parallel.
    """
    # (lower vertex, direction) in the cube's own frame, unit cube.
    lower = np.array([[1, 0, 0], [0, 1, 0], [0, 1, 0], [0, 0, 1], [0, 0, 1], [1, 0, 0]], float)
    direction = np.array([[0, 1, 0], [1, 0, 0], [0, 0, 1], [0, 1, 0], [1, 0, 0], [0, 0, 1]], float)
    centred = (lower - 0.5) * cube_edge_m
    rot = _diagonal_to_z()
    return centred @ rot.T, direction @ rot.T


def _diagonal_to_z() -> np.ndarray:
    """Rotation matrix taking the cube diagonal (1,1,1)/sqrt(3) to +z, x toward strut 1."""
    z = np.ones(3) / np.sqrt(3.0)
    x = np.array([1.0, -1.0, 0.0]) / np.sqrt(2.0)
    y = np.cross(z, x)
    return np.vstack([x, y, z])


@dataclass(frozen=True)
class CubicHexapodGeometry:
    """Cubic-configuration hexapod.

    Attributes:
        cube_edge_m: edge of the cube the strut lines lie on (m). Sets the lever arms.
        top_joint_offset_m: distance from the cube's lower vertices down each strut line
            to the top-plate joint (m).
        strut_length_m: joint-to-joint length of each strut at the nominal pose (m).
    """

    cube_edge_m: float = 0.040
    top_joint_offset_m: float = 0.03
    strut_length_m: float = 0.20
    unit_vectors: np.ndarray = field(init=False, repr=False)
    top_joints_m: np.ndarray = field(init=False, repr=False)
    base_joints_m: np.ndarray = field(init=False, repr=False)

    def __post_init__(self) -> None:
        """Compute joints and unit vectors; validate the dimensions."""
        for name in ("cube_edge_m", "top_joint_offset_m", "strut_length_m"):
            value = getattr(self, name)
            if not np.isfinite(value) or value <= 0.0:
                raise ValueError(f"{name} must be a positive finite length in m, got {value!r}")
        vertex, unit = _cube_strut_lines(self.cube_edge_m)
        top = vertex - self.top_joint_offset_m * unit
        base = top - self.strut_length_m * unit
        object.__setattr__(self, "unit_vectors", unit)
        object.__setattr__(self, "top_joints_m", top)
        object.__setattr__(self, "base_joints_m", base)

    @property
    def top_jacobian(self) -> np.ndarray:
        """Strut length rate per top-plate pose rate (6, 6): ``l_dot = J q_dot``."""
        return axial_jacobian(self.top_joints_m, self.unit_vectors)

    @property
    def base_jacobian(self) -> np.ndarray:
        """Axial displacement of the base joints per bottom-plate pose rate (6, 6)."""
        return axial_jacobian(self.base_joints_m, self.unit_vectors)

    def strut_lengths(self, pose: np.ndarray) -> np.ndarray:
        """Exact inverse kinematics: joint-to-joint strut lengths (m) at a top-plate pose.

        ``pose`` is ``[x, y, z, rx, ry, rz]`` with the rotation as a rotation vector (rad),
        the bottom plate at its nominal pose.
        """
        pose = np.asarray(pose, float)
        rot = Rotation.from_rotvec(pose[3:]).as_matrix()
        top = self.top_joints_m @ rot.T + pose[:3]
        return np.linalg.norm(top - self.base_joints_m, axis=1)

    def stroke_for_pose(self, pose: np.ndarray) -> np.ndarray:
        """Exact stroke (m) each strut needs to reach ``pose``: length minus nominal length."""
        return self.strut_lengths(pose) - self.strut_length_m

    def linearization_error(self, pose: np.ndarray) -> float:
        """Largest difference (m) between exact and Jacobian-predicted stroke at ``pose``."""
        exact = self.stroke_for_pose(pose)
        return float(np.max(np.abs(exact - self.top_jacobian @ np.asarray(pose, float))))

    def platform_from_struts(self, strut_values: np.ndarray) -> np.ndarray:
        """Top-plate 6-DOF quantity from axial strut quantities: ``J^-1 @ strut_values``.

        For the in-line accelerometers this turns six axial accelerations (m/s^2) into the
        top plate's ``[ax, ay, az, alpha_x, alpha_y, alpha_z]``; it accepts (6,) or (N, 6).
        """
        values = np.asarray(strut_values, float)
        return np.linalg.solve(self.top_jacobian, values.T).T

    def strut_forces_for_wrench(self, wrench: np.ndarray) -> np.ndarray:
        """Strut forces (N) that produce a wrench ``[Fx, Fy, Fz, Mx, My, Mz]`` (N, N m).

        Statics of the Jacobian: ``wrench = J^T f``.
        """
        return np.linalg.solve(self.top_jacobian.T, np.asarray(wrench, float))
