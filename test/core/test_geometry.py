"""Cubic Stewart geometry: orthogonality, decoupling, kinematics, ranges."""

import numpy as np
import pytest

from hexapod_vibration.core.model.geometry import CubicHexapodGeometry

GEO = CubicHexapodGeometry()


def test_struts_form_a_cube_neighbours_orthogonal_opposites_parallel():
    gram = GEO.unit_vectors @ GEO.unit_vectors.T
    expected = np.kron(np.ones((2, 2)), np.eye(3))
    np.testing.assert_allclose(gram, expected, atol=1e-12)
    assert np.all(GEO.unit_vectors[:, 2] > 0.57)   # all inclined 54.7 deg from z


def test_cubic_configuration_decouples_the_axes():
    jtj = GEO.top_jacobian.T @ GEO.top_jacobian
    off_diagonal = jtj - np.diag(np.diag(jtj))
    assert np.max(np.abs(off_diagonal)) < 1e-12 * np.max(np.abs(jtj))
    np.testing.assert_allclose(np.diag(jtj)[:3], 2.0, rtol=1e-12)  # sum of u_i^2 per axis


def test_inverse_kinematics_matches_jacobian_to_second_order():
    direction = np.array([1e-4, -2e-4, 3e-4, 2e-3, -1e-3, 4e-3])
    np.testing.assert_allclose(GEO.stroke_for_pose(np.zeros(6)), 0.0, atol=1e-15)
    err_1 = GEO.linearization_error(direction)
    err_half = GEO.linearization_error(direction / 2)
    assert err_1 < 1e-6
    assert err_half == pytest.approx(err_1 / 4, rel=0.05)


def test_platform_from_struts_inverts_the_jacobian():
    rng = np.random.default_rng(1)
    q = rng.normal(size=(10, 6))
    strut = q @ GEO.top_jacobian.T
    np.testing.assert_allclose(GEO.platform_from_struts(strut), q, atol=1e-12)


def test_paper_pointing_range_fits_in_the_stroke():
    limit = 5e-3
    for pose in ([0, 0, 0, np.deg2rad(2.5), 0, 0], [0, 0, 0, 0, np.deg2rad(2.5), 0],
                 [0, 0, 0, 0, 0, np.deg2rad(10.0)], [0, 0, 0, 0, 0, -np.deg2rad(10.0)]):
        assert np.max(np.abs(GEO.stroke_for_pose(pose))) < limit


def test_wrench_statics_is_the_jacobian_transpose():
    wrench = np.array([1.0, -2.0, 30.0, 0.1, -0.2, 0.05])
    forces = GEO.strut_forces_for_wrench(wrench)
    np.testing.assert_allclose(GEO.top_jacobian.T @ forces, wrench, atol=1e-10)


@pytest.mark.parametrize("bad", [0.0, -0.04, float("nan"), float("inf")])
def test_bad_dimensions_are_rejected(bad):
    with pytest.raises(ValueError, match="cube_edge_m"):
        CubicHexapodGeometry(cube_edge_m=bad)
