"""The fit's pixel model when the penumbra is one or two pixels wide: the blurred profile
(``softshadow.blurred_profile_alpha``, the renderer's, which the fitter uses) against an exact
convolution, its gradients, and one blur per photo."""

from __future__ import annotations

import dataclasses
import functools

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.stats import norm

from softshadow import Pose, blurred_profile_alpha, profile_alpha
from softshadow.internal import WIDE_BLUR_TAU

from test_fit_model import K, _oblique_view
from gradcheck import assert_jacobian_matches_central_differences

# A dense Riemann sum over the Gaussian (step 3e-3 sigma out to 9 sigma): the reference.
_Z = np.linspace(-9.0, 9.0, 6001)
_WZ = norm.pdf(_Z) / norm.pdf(_Z).sum()


def _reference(u, tau, profile):
    u, tau = np.broadcast_arrays(np.asarray(u, float), np.asarray(tau, float))
    x = u[..., None] + tau[..., None] * _Z
    if profile == "linear":
        return np.clip(0.5 * (1.0 - x), 0.0, 1.0) @ _WZ
    return np.asarray(profile_alpha(jnp.asarray(x), profile)) @ _WZ


@pytest.mark.parametrize("profile", ["disk", "linear"])
def test_blurred_profile_matches_the_exact_convolution_for_any_blur(profile):
    """From no blur to a blur five times the penumbra's half-width (a 1 px penumbra under a
    camera blur of 2 px), within 2e-4 everywhere; in float32 too."""
    u = np.linspace(-12.0, 12.0, 241)
    for tau in (0.0, 0.05, 0.0999, 0.1, 0.3, 1.0, 2.0, 5.0):
        ref = _reference(u, tau, profile)
        with jax.enable_x64(True):
            got = np.asarray(blurred_profile_alpha(jnp.asarray(u), jnp.full(u.shape, tau), profile))
        np.testing.assert_allclose(got, ref, atol=2e-4, err_msg=f"tau {tau}")
        got32 = blurred_profile_alpha(jnp.asarray(u, jnp.float32), jnp.full(u.shape, tau, jnp.float32), profile)
        assert got32.dtype == jnp.float32
        np.testing.assert_allclose(np.asarray(got32), ref, atol=3e-4, err_msg=f"float32, tau {tau}")


@settings(deadline=None)
@given(u=st.floats(-3.0, 3.0), tau=st.floats(0.0, 4.0), profile=st.sampled_from(["disk", "linear"]))
def test_blurred_profile_gradients_match_finite_differences(u, tau, profile):
    """d alpha / d(u, tau) by autodiff against central differences in float64, at generic points
    (away from the branch switch at WIDE_BLUR_TAU and the unblurred ramp's kinks)."""
    h = 1e-6
    if abs(tau - WIDE_BLUR_TAU) < 10 * h or tau < 0.02:
        tau = tau + 0.05
    with jax.enable_x64(True):
        f = lambda a, b: blurred_profile_alpha(a, b, profile)
        du, dt = jax.grad(f, argnums=(0, 1))(jnp.float64(u), jnp.float64(tau))
        fd_u = (float(f(u + h, tau)) - float(f(u - h, tau))) / (2 * h)
        fd_t = (float(f(u, tau + h)) - float(f(u, tau - h))) / (2 * h)
    assert np.isfinite([float(du), float(dt)]).all()
    np.testing.assert_allclose([float(du), float(dt)], [fd_u, fd_t], atol=1e-6)


@pytest.mark.parametrize("profile", ["disk", "linear"])
def test_blurred_profile_is_finite_with_its_gradients_at_hard_points(profile):
    """No blur, the branch switch, the ramp's ends and far outside: values in [0, 1] and finite
    gradients (float64 and float32)."""
    for dtype in (jnp.float64, jnp.float32):
        with jax.enable_x64(dtype == jnp.float64):
            for u in (-1.0, 1.0, 0.0, -40.0, 40.0):
                for tau in (0.0, 1e-7, WIDE_BLUR_TAU, 1e3):
                    f = lambda a, b: blurred_profile_alpha(a, b, profile)
                    a = float(f(jnp.asarray(u, dtype), jnp.asarray(tau, dtype)))
                    g = jax.grad(f, argnums=(0, 1))(jnp.asarray(u, dtype), jnp.asarray(tau, dtype))
                    assert -1e-6 <= a <= 1 + 1e-6, (u, tau, a)
                    assert np.isfinite([float(x) for x in g]).all(), (u, tau, g)


@pytest.mark.parametrize("profile", ["disk", "linear"])
def test_blurred_profile_vectorised_jvp_and_float32_gradients(profile):
    """The forward-mode derivative over arrays (as the fitter's Jacobian takes it) matches central
    differences in float64 on both sides of WIDE_BLUR_TAU; float32 gradients follow float64's;
    with no blur it is ``profile_alpha`` itself."""
    u = np.linspace(-2.7, 2.9, 23)
    tau = np.geomspace(0.03, 3.1, 23)
    du, dtau = np.cos(np.arange(23.0)), np.sin(np.arange(23.0) + 0.5)
    f = jax.jit(lambda a, b: blurred_profile_alpha(a, b, profile))  # one compilation per dtype, not an op each
    grads = jax.jit(jax.vmap(jax.grad(f, argnums=(0, 1))))
    with jax.enable_x64(True):
        _, tangent = jax.jit(lambda a, b, da, db: jax.jvp(f, (a, b), (da, db)))(u, tau, du, dtau)
        h = 1e-6
        fd = (np.asarray(f(u + h * du, tau + h * dtau)) - np.asarray(f(u - h * du, tau - h * dtau))) / (2 * h)
        np.testing.assert_allclose(np.asarray(tangent), fd, atol=1e-6)
        g64 = np.stack(grads(u, tau))
        sharp = np.asarray(profile_alpha(jnp.asarray(u), profile))
        np.testing.assert_allclose(np.asarray(f(u, np.zeros_like(u))), sharp, atol=1e-12)
    g32 = grads(jnp.asarray(u, jnp.float32), jnp.asarray(tau, jnp.float32))
    assert all(g.dtype == jnp.float32 for g in g32)
    np.testing.assert_allclose(np.stack(g32), g64, atol=2e-4)


@functools.cache
def _view_samples(max_samples):
    from fitting.samples.ground import select_samples
    _, _, view = _oblique_view()
    from softshadow import SoftShadowModel
    model = SoftShadowModel.from_mesh("pillar", profile="disk")
    return view, select_samples(model, Pose(), view, range_k_max=0.03, max_samples=max_samples, seed=0)


def _group(n_photos=1, max_samples=300):
    from fitting.solve.group import _group_arrays
    view, samples = _view_samples(max_samples)
    return samples, _group_arrays([samples] * n_photos, [view] * n_photos)


def test_fit_model_alpha_is_the_exact_convolution_when_the_blur_exceeds_the_penumbra():
    """The fitter's alpha for a narrow penumbra (k = 0.002, under a pixel wide on this 320x240
    view) under a 0.9 px camera blur is the exact convolution of the disk profile with a Gaussian
    of variance 1/12 + 0.81 px^2. Gauss-Hermite over that blur was off by up to 0.05 here."""
    from fitting.solve.model import FitConfig, angular_pixel_gradient, edge_terms, raw_from_k
    samples, group = _group()
    n = len(samples.observed)
    k = 0.002
    group = dataclasses.replace(group, grad_t_pixel=angular_pixel_gradient(group, Pose(), K, "edge"))
    config = FitConfig.make("disk", fit_blur=True)
    shape = jnp.asarray([float(raw_from_k(k)), 0.0, 0.0, 0.81])
    alpha, u, slope = (np.asarray(x)[:n] for x in edge_terms(shape, group, Pose(), config))
    tau = np.sqrt(1 / 12 + 0.81) * slope
    near = (np.abs(u) < 1 + 3 * tau) & (slope > 0)
    assert near.sum() >= 20 and np.median(2 / slope[near & (np.abs(u) < 1)]) < 1.5
    np.testing.assert_allclose(alpha[near], _reference(u[near], tau[near], "disk"), atol=2e-4)


def test_each_photo_has_its_own_blur_and_its_jacobian_matches_finite_differences():
    """Two photos of one group with different blurs: each blur moves only its own photo's
    residuals, and the solver's Jacobian (the per-sample blur JVP) matches central differences."""
    from fitting.solve.model import FitConfig, FitParams, raw_from_k, residuals
    from fitting.solve.group import _prepare, initial_params
    samples, group = _group(n_photos=2)
    params, _ = initial_params([samples, samples])
    config = FitConfig.make("disk", True, True, 0.05, "edge")
    grad_t, _ = _prepare(params, jnp.asarray(raw_from_k(np.array([K]))), group, Pose(), config)
    group = dataclasses.replace(group, grad_t_pixel=grad_t)
    params = dataclasses.replace(params, raw_k=jnp.asarray(float(raw_from_k(0.004))),
                                 raw_blur=jnp.asarray([0.2, 0.9]), sun_delta_deg=jnp.asarray([0.1, -0.05]))
    lay = FitParams.layout(2)
    assert lay["raw_blur"].stop - lay["raw_blur"].start == 2
    flat = params.vector()
    fn = jax.jit(lambda x: residuals(FitParams.from_vector(x, 2), (group, Pose(), config)))
    jac = np.asarray(jax.jacfwd(fn)(flat))
    n = len(samples.observed)
    photo = np.asarray(group.photo)
    real = np.arange(len(photo)) < 2 * n
    for j, p in enumerate(range(lay["raw_blur"].start, lay["raw_blur"].stop)):
        assert np.abs(jac[real & (photo == j), p]).max() > 1e-3, "a photo's blur must move its residuals"
        assert np.abs(jac[real & (photo != j), p]).max() == 0.0, "and no other photo's"
    assert_jacobian_matches_central_differences(fn, np.asarray(flat), jac)
