"""The fit's steps one by one (``fitting.solve.group``): parameter layout, covariance, the k/rho
transform, penumbra widths, the sample counts the rule book judges, and the robust scale (the rules
themselves: tests/test_verdict_rules.py)."""

from __future__ import annotations

import dataclasses

import jax.numpy as jnp
import numpy as np
import pytest

from fitting.samples.photo_samples import PhotoSamples
from fitting.solve.model import FitParams, Prediction, k_from_raw, rho_from_raw
from fitting.solve.evidence import no_ramp_k, penumbra_px_per_k
from fitting.solve.group import (UMBRA_ALPHA, SampleCounts, covariance, k_rho_with_errors, penumbra_width_px,
                                 robust_delta, sample_counts)


def _params(n_photos=3, seed=0):
    rng = np.random.default_rng(seed)
    f = lambda *shape: jnp.asarray(rng.normal(size=shape))
    return FitParams(raw_k=f(), raw_rho=f(), raw_blur=f(n_photos), sun_delta_deg=f(2), log_level=f(n_photos, 2),
                     gradient=f(n_photos, 2))


def test_parameter_vector_layout_names_every_entry_and_round_trips():
    params = _params(3)
    x = np.asarray(params.vector())
    lay = FitParams.layout(3)
    assert x.shape == (4 + 5 * 3,)
    for name, where in lay.items():
        np.testing.assert_array_equal(x[where], np.ravel(getattr(params, name)), err_msg=name)
    back = FitParams.from_vector(jnp.asarray(x), 3)
    for name in lay:
        np.testing.assert_array_equal(getattr(back, name), getattr(params, name))


def _jac_with_singular_values(s, n=200, seed=1):
    """J (n, p) = U diag(s) V^T with known singular values; also V."""
    rng = np.random.default_rng(seed)
    u, _ = np.linalg.qr(rng.normal(size=(n, len(s))))
    v, _ = np.linalg.qr(rng.normal(size=(len(s), len(s))))
    return (u * s) @ v.T, v


def test_covariance_matches_the_normal_equations_when_well_conditioned():
    rng = np.random.default_rng(0)
    jac = rng.normal(size=(300, 6))
    r = rng.normal(size=300)
    cov, s2 = covariance(r, jac, 300)
    assert s2 == pytest.approx(float(r @ r) / (300 - 6))
    np.testing.assert_allclose(cov, np.linalg.inv(jac.T @ jac) * s2, rtol=1e-10, atol=1e-14)


def test_covariance_keeps_a_badly_conditioned_direction_that_normal_equations_lose():
    """cond(J) = 1e5: the normal equations (condition 1e10) lose about six digits, the SVD
    of J about one."""
    s = np.array([1.0, 0.3, 1e-3, 1e-5])
    jac, v = _jac_with_singular_values(s)
    r = np.full(200, np.sqrt((200 - 4) / 200))  # s2 = 1
    cov, s2 = covariance(r, jac, 200)
    exact = (v / s**2) @ v.T * s2
    error = lambda c: np.abs(c - exact).max() / np.abs(exact).max()
    assert error(cov) < 1e-10
    assert error(np.linalg.pinv(jac.T @ jac, rcond=1e-12) * s2) > 1e-7  # what the SVD avoids


def test_covariance_gives_switched_off_parameters_zero_variance():
    rng = np.random.default_rng(2)
    jac = rng.normal(size=(100, 5))
    jac[:, 2] = 0.0  # a term switched off (e.g. blur when not fitted)
    cov, s2 = covariance(rng.normal(size=100), jac, 100)
    assert np.abs(cov[2]).max() < 1e-15 and np.abs(cov[:, 2]).max() < 1e-15
    keep = [0, 1, 3, 4]
    sub = jac[:, keep]
    np.testing.assert_allclose(cov[np.ix_(keep, keep)], np.linalg.inv(sub.T @ sub) * s2, rtol=1e-10)


@pytest.mark.parametrize("raw_k, raw_rho", [(-1.3, -0.8), (0.4, 1.7), (2.5, 0.0)])
def test_k_rho_errors_follow_the_reparameterisation(raw_k, raw_rho):
    """sigma_k = |dk/draw_k| sigma_raw (finite differences of k_from_raw), same for rho."""
    params = dataclasses.replace(_params(2), raw_k=jnp.asarray(raw_k), raw_rho=jnp.asarray(raw_rho))
    p = len(np.asarray(params.vector()))
    lay = FitParams.layout(2)
    cov = np.diag(np.linspace(0.5, 2.0, p))
    est = k_rho_with_errors(params, cov)
    h = 1e-6
    dk = (float(k_from_raw(raw_k + h)) - float(k_from_raw(raw_k - h))) / (2 * h)
    drho = (float(rho_from_raw(raw_rho + h)) - float(rho_from_raw(raw_rho - h))) / (2 * h)
    assert est.range_k == pytest.approx(float(k_from_raw(raw_k)), rel=1e-12)
    assert est.rho == pytest.approx(float(rho_from_raw(raw_rho)), rel=1e-12)
    assert est.range_stderr == pytest.approx(abs(dk) * np.sqrt(cov[lay["raw_k"], lay["raw_k"]][0, 0]), rel=1e-6)
    assert est.rho_stderr == pytest.approx(abs(drho) * np.sqrt(cov[lay["raw_rho"], lay["raw_rho"]][0, 0]), rel=1e-6)


class _Samples(PhotoSamples):
    """A photo's samples of which only the count matters (``observed``)."""

    def __init__(self, n):
        self.observed = np.zeros(n)


def test_penumbra_width_is_two_over_the_pixel_slope_inside_the_penumbra():
    u = np.array([-2.0, -0.5, 0.0, 0.5, 3.0, 0.2])
    slope = np.array([9.0, 0.5, 0.25, 1.0, 9.0, 0.5])  # widths 4, 8, 2, 4 px inside |u| < 1
    pred = Prediction(np.zeros(6), np.zeros(6), u, slope)
    median, iqr = penumbra_width_px([_Samples(4), _Samples(2)], pred)
    assert median == pytest.approx(4.0)
    assert iqr == pytest.approx(np.subtract(*np.percentile([4.0, 8.0, 2.0, 4.0], [75, 25])))
    none = Prediction(np.zeros(2), np.zeros(2), np.array([2.0, -3.0]), np.ones(2))
    assert penumbra_width_px([_Samples(2)], none) == (None, None)


def test_penumbra_px_per_k_is_the_outlines_width_per_unit_k_at_any_k():
    # u = distance / half-width, and the half-width is k * 190 px: |du/dpixel| = 1 / (190 k).
    rng = np.random.default_rng(3)
    for k in (1e-7, 5e-4, 0.02):
        distance_px = rng.uniform(-400.0, 400.0, 500)
        u = distance_px / (190.0 * k)
        slope = np.full(500, 1.0 / (190.0 * k))
        u[:50] = 1e6  # beyond the planned bands: no geometry there
        assert penumbra_px_per_k(u, slope, k) == pytest.approx(380.0)
    assert penumbra_px_per_k(np.array([1e6, -1e6]), np.ones(2), 5e-4) is None
    assert penumbra_px_per_k(np.array([3.0]), np.ones(1), 0.0) is None


def test_no_ramp_k_is_the_k_whose_penumbra_reaches_the_nearest_sample():
    """No sample inside the penumbra: u scales as 1/k, so k * min |u| is the largest k the samples
    allow; samples beyond the planned bands (u = +-1e6) bound nothing, and a sample inside the
    penumbra leaves nothing to bound."""
    assert no_ramp_k(np.array([30.0, -17.0, 1e6, -1e6, 25.0]), 5e-4) == pytest.approx(17.0 * 5e-4)
    assert no_ramp_k(np.array([1e6, -1e6]), 5e-4) is None
    assert no_ramp_k(np.array([30.0, 0.5]), 5e-4) is None


def test_sample_counts_inside_the_penumbra_and_in_the_umbra_leave_out_the_padding():
    u = np.array([-2.0, -0.5, 0.99, 1.0, 3.0, 0.2, 0.0, -5.0])
    alpha = np.array([1.0, 0.7, 0.0, 0.0, 0.0, 0.4, UMBRA_ALPHA, 1.0])
    pred = Prediction(np.zeros(8), alpha, u, np.ones(8))
    # 6 real samples (4 + 2); the last two rows are padding.
    assert sample_counts([_Samples(4), _Samples(2)], pred) == SampleCounts(penumbra=3, umbra=1)
    assert sample_counts([_Samples(8)], pred) == SampleCounts(penumbra=4, umbra=3)


def test_robust_scale_is_three_normal_sigmas_and_ignores_padding():
    rng = np.random.default_rng(0)
    r = np.concatenate([rng.normal(0, 0.02, 20000), np.zeros(5000), rng.normal(0, 5.0, 500)])
    assert robust_delta(r, True) == pytest.approx(3 * 0.02, rel=0.05)
    assert robust_delta(r, False) == 0.0
    assert robust_delta(np.zeros(10), True) == pytest.approx(3e-3)


def test_remaining_step_is_zero_at_a_least_squares_solution_and_counts_errors_away_from_it():
    """A linear model in (raw_k, raw_rho, one more parameter): at its least-squares solution one more
    Gauss-Newton step moves nothing; from a point 0.3 away in raw_rho it moves rho by 0.3 sigmoid'
    over rho's error."""
    from fitting.solve.evidence import remaining_step_se
    rng = np.random.default_rng(3)
    n_photos = 1
    p = 4 + 5 * n_photos  # FitParams.layout
    jac = np.zeros((200, p))
    jac[:, :3] = rng.normal(size=(200, 3))
    truth = np.zeros(p)
    truth[:3] = (-1.0, 0.4, 0.2)
    y = jac @ truth + 0.01 * rng.normal(size=200)
    best = np.zeros(p)
    best[:3] = np.linalg.lstsq(jac[:, :3], y, rcond=None)[0]
    at = lambda x: FitParams.from_vector(x, n_photos)
    k_se, rho_se = 1e-4, 1e-3
    assert remaining_step_se(at(best), jac @ best - y, jac, k_se, rho_se) < 1e-6
    off = best.copy()
    off[1] += 0.3
    rho = lambda raw: 1.0 / (1.0 + np.exp(-raw))
    expected = abs(rho(best[1]) - rho(off[1])) / rho_se
    assert remaining_step_se(at(off), jac @ off - y, jac, k_se, rho_se) == pytest.approx(expected, rel=1e-6)
    assert np.isnan(remaining_step_se(at(off), np.full(200, np.nan), jac, k_se, rho_se))
    assert np.isnan(remaining_step_se(at(off), jac @ off - y, jac, 0.0, rho_se))
