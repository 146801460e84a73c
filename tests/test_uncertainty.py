"""The stated errors (``fitting.solve.uncertainty``): edge clusters, the cluster-robust covariance,
the systematic floor and how the parts combine. Small NumPy problems with known answers."""

from __future__ import annotations

import numpy as np
import pytest

from fitting.solve.group import covariance
from fitting.solve.uncertainty import (CALIBRATED_EDGE_FLOOR, CALIBRATED_FLOOR, EdgeFloor, edge_rho_errors, profile_spread,
                                 SystematicFloor, cluster_covariance, combine_errors,
                                 edge_clusters, systematic_errors)


def test_edge_clusters_cut_each_photos_profiles_into_runs_and_mark_padding():
    ids = [np.array([0, 0, 1, 2, 3, 3, 4, 5]), np.array([10, 12, 12, 14])]
    c = edge_clusters(ids, 14, per_photo=3)
    # Photo 0: six profile ids (0..5) in three runs of two; photo 1: three ids in three runs.
    np.testing.assert_array_equal(c[:8], [0, 0, 0, 1, 1, 1, 2, 2])
    np.testing.assert_array_equal(c[8:12], [3, 4, 4, 5])
    np.testing.assert_array_equal(c[12:], [-1, -1])


def _grouped_design(n_clusters, per_cluster, tau, sigma, seed):
    """y = 1 + u_c + e: an intercept-only design J (n, 1) and residuals about the mean."""
    rng = np.random.default_rng(seed)
    clusters = np.repeat(np.arange(n_clusters), per_cluster)
    y = 1.0 + rng.normal(0, tau, n_clusters)[clusters] + rng.normal(0, sigma, len(clusters))
    jac = np.ones((len(y), 1))
    return y - y.mean(), jac, clusters


def test_cluster_covariance_reads_the_variance_of_clustered_noise_that_the_classic_one_misses():
    """Residuals sharing a per-cluster offset: the mean's true variance is (tau^2 + sigma^2/m)/G.
    The classic covariance sees n independent residuals and is far too small."""
    g, m, tau, sigma = 60, 40, 0.05, 0.05
    r, jac, clusters = _grouped_design(g, m, tau, sigma, seed=3)
    true_sd = np.sqrt((tau ** 2 + sigma ** 2 / m) / g)
    robust = float(np.sqrt(cluster_covariance(r, jac, clusters)[0, 0]))
    classic = float(np.sqrt(covariance(r, jac, len(r))[0][0, 0]))
    assert 0.75 < robust / true_sd < 1.3
    assert classic < 0.3 * true_sd


def test_cluster_covariance_of_independent_noise_matches_the_classic_one():
    rng = np.random.default_rng(0)
    jac = rng.normal(size=(4000, 3))
    r = rng.normal(0, 0.1, 4000)
    r -= jac @ np.linalg.lstsq(jac, r, rcond=None)[0]  # residuals at the least-squares solution
    clusters = np.arange(4000) // 20
    robust = np.sqrt(np.diag(cluster_covariance(r, jac, clusters)))
    classic = np.sqrt(np.diag(covariance(r, jac, 4000)[0]))
    np.testing.assert_allclose(robust, classic, rtol=0.2)


def test_cluster_covariance_ignores_padding_rows_and_needs_two_clusters():
    r, jac, clusters = _grouped_design(10, 5, 0.1, 0.1, seed=1)
    padded = cluster_covariance(np.concatenate([r, [5.0, -5.0]]), np.vstack([jac, [[1.0], [1.0]]]),
                                np.concatenate([clusters, [-1, -1]]))
    np.testing.assert_allclose(padded, cluster_covariance(r, jac, clusters))
    assert np.isnan(cluster_covariance(r, jac, np.zeros(len(r), int))).all()


def test_cluster_covariance_gives_a_switched_off_parameter_zero_variance():
    r, jac, clusters = _grouped_design(12, 10, 0.1, 0.1, seed=2)
    jac = np.hstack([jac, np.zeros_like(jac)])  # a term switched off: a zero column
    cov = cluster_covariance(r, jac, clusters)
    assert np.isfinite(cov).all() and cov[1, 1] == 0.0 and cov[0, 0] > 0


@pytest.mark.parametrize("penumbra_px, expected_rel", [(4.0, np.hypot(0.03, 0.2 / 4)), (None, np.hypot(0.03, 0.4)),
                                                       (0.1, np.hypot(0.03, 0.4))])
def test_systematic_error_of_k_grows_as_the_penumbra_narrows(penumbra_px, expected_rel):
    floor = SystematicFloor(k_rel=0.03, k_rel_px=0.2, rho_abs=0.004, rho_rel=0.02)
    sk, sr = systematic_errors(0.006, 0.3, penumbra_px, floor)
    assert sk == pytest.approx(0.006 * expected_rel)
    assert sr == pytest.approx(np.hypot(0.004, 0.02 * 0.3))


def test_combined_error_is_the_larger_statistical_part_and_the_systematic_one_in_quadrature():
    floor = SystematicFloor(0.05, 0.0, 0.003, 0.0)
    u = combine_errors(0.01, 0.2, classic=(1e-4, 0.001), robust=(3e-4, float("nan")), penumbra_px=3.0, floor=floor)
    assert u.range_stderr_stat == pytest.approx(3e-4) and u.rho_stderr_stat == pytest.approx(0.001)
    assert u.range_stderr_sys == pytest.approx(5e-4) and u.rho_stderr_sys == pytest.approx(0.003)
    assert u.range_stderr == pytest.approx(np.hypot(3e-4, 5e-4))
    assert u.rho_stderr == pytest.approx(np.hypot(0.001, 0.003))


def test_the_calibrated_floor_is_positive():
    """The shipped floor comes from the calibration (docs/uncertainty.md): a zero would make the
    stated errors statistical only again."""
    assert CALIBRATED_FLOOR.k_rel > 0 or CALIBRATED_FLOOR.k_rel_px > 0
    assert CALIBRATED_FLOOR.rho_abs > 0 or CALIBRATED_FLOOR.rho_rel > 0


def test_profile_spread_is_the_normal_scaled_mad_of_log_rho():
    rng = np.random.default_rng(0)
    log_rho = np.log(0.2) + 0.1 * rng.normal(size=4000)
    assert profile_spread(log_rho) == pytest.approx(0.1, rel=0.05)
    # One wild profile does not move it; one profile alone has no spread.
    assert profile_spread(np.r_[log_rho, 50.0]) == pytest.approx(profile_spread(log_rho), rel=0.01)
    assert profile_spread(np.array([np.log(0.2)])) == 0.0


def test_edge_rho_error_adds_the_floor_and_the_profile_spread_in_quadrature():
    floor = EdgeFloor(rho_abs=0.003, rho_rel=0.04, rho_spread=0.5)
    e = edge_rho_errors(0.25, 0.006, 0.2, floor)
    sys = np.sqrt(0.003 ** 2 + (0.04 * 0.25) ** 2 + (0.5 * 0.25 * 0.2) ** 2)
    assert e.rho_stderr_sys == pytest.approx(sys) and e.rho_stderr_stat == 0.006
    assert e.rho_stderr == pytest.approx(np.hypot(0.006, sys))
    assert np.isnan(e.range_stderr) and np.isnan(e.range_stderr_sys)
    # More disagreement between profiles, a larger error; no floor, the bootstrap alone.
    assert edge_rho_errors(0.25, 0.006, 0.4, floor).rho_stderr > e.rho_stderr
    assert edge_rho_errors(0.25, 0.006, 0.4, EdgeFloor(0.0, 0.0, 0.0)).rho_stderr == pytest.approx(0.006)
    assert CALIBRATED_EDGE_FLOOR.rho_rel > 0 or CALIBRATED_EDGE_FLOOR.rho_abs > 0


def test_resolution_warning_names_a_penumbra_under_the_blur_spot_only():
    """Warned when the penumbra is narrower than 3 sigma of pixel area plus camera blur
    (3 sqrt(1/12 + 0.7^2) = 2.27 px), quiet at and above it, and when nothing was measured."""
    from fitting.verdict.rules import RESOLVED_BLUR_WIDTHS, resolution_warning
    spot = RESOLVED_BLUR_WIDTHS * np.sqrt(1 / 12 + 0.7 ** 2)
    text = resolution_warning(1.2, 0.7)
    assert text is not None and text.startswith("penumbra 1.2 px wide") and "2.3 px" in text
    assert "\n" not in text
    assert resolution_warning(spot + 1e-9, 0.7) is None
    assert resolution_warning(3.0, 0.7) is None
    # Without a fitted blur the spot is the pixel's own area: 3 sqrt(1/12) = 0.87 px.
    assert resolution_warning(0.8, None) is not None and resolution_warning(0.9, None) is None
    assert resolution_warning(None, 0.7) is None and resolution_warning(float("nan"), 0.7) is None
