"""The renderer's error floor: each pixel's footprint integrated in penumbra units, and the sky
the object hides (docs/renderer.md, "Pixel footprint, hidden sky and corners").

- ``footprint_profile_alpha`` against a brute-force mean over the pixel, and its gradients
  (float64 autodiff against finite differences at generic points; finite at the hard cases:
  no footprint, a footprint along one axis only, the out-of-band sentinels, the ramp's ends;
  the float32 path).
- A ground map with the footprint against the block mean of a 6x finer point-sampled map.
- The hidden sky: a ground map with it is the map without it less rho h, with h the
  ``hidden_sky_fraction`` of the pixel (interpolated from its node grid).
- The renderer's gradients with both terms on (the plan, which holds h, fixed): the point
  property test with a pixel footprint, and a ground map.
"""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
import numpy as np
import pytest
import trimesh
from hypothesis import given, settings
from hypothesis import strategies as st

from gradcheck import PARAM_NAMES, STEPS, check_point_gradients, unpack
from softshadow import GroundGrid, Pose, ShadowParams, SoftShadowModel, Sun, profile_alpha
from softshadow.internal import footprint_profile_alpha, hidden_sky_fraction, profile_integral
from softshadow.meshes import builtin_mesh
from test_render_gradients import pillar_shadow_samples, scene, theta_of


def brute_mean(u0, du_a, du_b, profile, n=300):
    """Mean of profile_alpha over the pixel, on an n x n grid of sub-pixel points (NumPy)."""
    s = (np.arange(n) + 0.5) / n - 0.5
    u = u0 + du_a * s[:, None] + du_b * s[None, :]
    uc = np.clip(u, -1.0, 1.0)
    if profile == "linear":
        return float(np.mean(0.5 * (1.0 - uc)))
    return float(np.mean((np.arccos(uc) - uc * np.sqrt(1.0 - uc * uc)) / np.pi))


@pytest.mark.parametrize("profile", ["linear", "disk"])
def test_footprint_mean_matches_brute_force(profile):
    rng = np.random.default_rng(4)
    worst = 0.0
    for _ in range(60):
        u0 = rng.uniform(-3.0, 3.0)
        du_a, du_b = rng.uniform(-4.0, 4.0, 2) * 10.0 ** rng.uniform(-2.5, 0.5, 2)
        got = float(footprint_profile_alpha(u0, du_a, du_b, profile))
        worst = max(worst, abs(got - brute_mean(u0, du_a, du_b, profile)))
    assert worst < 1.5e-3, f"footprint mean off by {worst:.2e}"  # measured 2.6e-4 against 400 x 400


@pytest.mark.parametrize("profile", ["linear", "disk"])
def test_no_footprint_is_the_point_value_and_the_integral_is_the_antiderivative(profile):
    u = jnp.linspace(-2.0, 2.0, 41) + 0.013
    np.testing.assert_allclose(footprint_profile_alpha(u, 0.0, 0.0, profile), profile_alpha(u, profile),
                               atol=1e-12)
    # profile_integral' = profile_alpha, and the integral of alpha over [-1, 1] is 1 for both profiles.
    np.testing.assert_allclose(jax.vmap(jax.grad(lambda x: profile_integral(x, profile)))(u),
                               profile_alpha(u, profile), atol=1e-12)
    assert float(profile_integral(1.0, profile) - profile_integral(-1.0, profile)) == pytest.approx(1.0)
    # A sub-pixel penumbra seen by a whole pixel: the box's linear ramp across it.
    assert float(footprint_profile_alpha(0.0, 40.0, 0.0, profile)) == pytest.approx(0.5, abs=1e-9)
    assert float(footprint_profile_alpha(-10.0, 40.0, 0.0, profile)) == pytest.approx(0.75, abs=1e-3)


@functools.partial(jax.jit, static_argnames="profile")
def _values_and_grads(x, profile):
    """footprint_profile_alpha and its gradient in (u, du_a, du_b) at rows x (n, 3)."""
    f = lambda v: footprint_profile_alpha(v[0], v[1], v[2], profile)
    return jax.vmap(jax.value_and_grad(f))(x)


@pytest.mark.parametrize("profile", ["linear", "disk"])
@given(u0=st.floats(-2.5, 2.5), du_a=st.floats(0.05, 3.0), du_b=st.floats(-3.0, 3.0))
def test_footprint_gradients_match_finite_differences(profile, u0, du_a, du_b):
    x0 = np.array([u0, du_a, du_b])
    eps = 1e-6
    rows = np.vstack([x0, x0 + eps * np.eye(3), x0 - eps * np.eye(3)])
    values, grads = (np.asarray(a) for a in _values_and_grads(jnp.asarray(rows), profile))
    fd = (values[1:4] - values[4:7]) / (2 * eps)
    for i in range(3):
        assert abs(grads[0, i] - fd[i]) <= 1e-5 + 1e-4 * abs(fd[i]), (
            f"d/d{('u', 'du_a', 'du_b')[i]}: {grads[0, i]} vs {fd[i]}")


@pytest.mark.parametrize("profile", ["linear", "disk"])
def test_footprint_is_finite_at_the_hard_cases(profile):
    cases = jnp.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [-1.0, 0.0, 0.0], [1.0, 0.5, 0.0], [0.3, 0.0, 0.7],
                       [1e6, 0.2, 0.1], [-1e6, 0.2, 0.1], [1e6, 0.0, 0.0], [0.2, 1e-9, 1e-9],
                       [0.5, 2e-3, 2e-3], [-0.999, 1e-3, 0.0], [0.1, 50.0, 50.0]])
    values, grads = (np.asarray(a) for a in _values_and_grads(cases, profile))
    assert np.all(np.isfinite(values)) and np.all(np.isfinite(grads))
    assert np.all((values >= -1e-9) & (values <= 1.0 + 1e-9))
    np.testing.assert_allclose(values[5:8], [0.0, 1.0, 0.0], atol=1e-12)


def test_footprint_float32_matches_float64():
    rng = np.random.default_rng(2)
    x = np.column_stack([rng.uniform(-2.5, 2.5, 500), rng.uniform(-3, 3, 500) * 10.0 ** rng.uniform(-2, 0.5, 500),
                         rng.uniform(-3, 3, 500)])
    for profile in ("linear", "disk"):
        ref = np.asarray(footprint_profile_alpha(*x.T, profile))
        with jax.enable_x64(False):
            single, g = _values_and_grads(jnp.asarray(x, jnp.float32), profile)
        single = np.asarray(single)
        assert single.dtype == np.float32
        assert np.max(np.abs(single - ref)) < 2e-4
        assert np.all(np.isfinite(np.asarray(g)))


@functools.cache
def pillar(profile="disk", footprint=True, hidden_sky=True) -> SoftShadowModel:
    return SoftShadowModel.from_mesh(builtin_mesh("pillar"), profile=profile, footprint=footprint,
                                     hidden_sky=hidden_sky)


SUN, POSE, PARAMS = Sun(200.0, 40.0), Pose(rotation_deg=(0.0, 0.0, 7.0)), ShadowParams(0.0047, 0.2)


@pytest.mark.parametrize("profile", ["linear", "disk"])
def test_ground_map_footprint_equals_the_mean_of_a_finer_point_sampled_map(profile):
    """Near the base the penumbra is narrower than a pixel: point sampling aliases, the footprint
    does not. The finer map's 8 x 8 block mean is the pixel's mean up to its own sampling."""
    grid = GroundGrid.around((0.25, 0.5), 0.8, 32)   # 2.5 cm pixels; the penumbra is 0-1 cm wide
    fine = GroundGrid.around((0.25, 0.5), 0.8, 256)
    new = np.asarray(pillar(profile, True, False).ground_map(PARAMS, SUN, POSE, grid))
    old = np.asarray(pillar(profile, False, False).ground_map(PARAMS, SUN, POSE, grid))
    ref = np.asarray(pillar(profile, False, False).ground_map(PARAMS, SUN, POSE, fine))
    ref = ref.reshape(32, 8, 32, 8).mean(axis=(1, 3))
    # Pixels across the shadow's edge, not those beside the pillar's own footprint (under the
    # pillar the ground is in shadow whatever its penumbra: a straddling pixel mixes it in).
    centres = grid.pixel_centres()
    beside = np.hypot(centres[..., 0], centres[..., 1]) < 0.2
    edge = (np.abs(ref - 0.5 * (1.0 + PARAMS.rho)) < 0.35) & ~beside
    assert edge.sum() > 25
    err_new = np.sqrt(np.mean((new - ref)[edge] ** 2))
    err_old = np.sqrt(np.mean((old - ref)[edge] ** 2))
    assert err_new < 0.012, f"footprint map vs 6x block mean: RMS {err_new:.4f} (point sampling {err_old:.4f})"
    assert err_new < 0.25 * err_old


def test_hidden_sky_is_rho_h_with_h_the_sky_fraction_of_the_pixel():
    grid = GroundGrid.around((0.3, 0.5), 2.4, 64)
    with_sky = np.asarray(pillar("disk", True, True).ground_map(PARAMS, SUN, POSE, grid))
    without = np.asarray(pillar("disk", True, False).ground_map(PARAMS, SUN, POSE, grid))
    h = (without - with_sky) / PARAMS.rho
    world = builtin_mesh("pillar").copy()
    world.apply_transform(trimesh.transformations.rotation_matrix(np.radians(7.0), (0, 0, 1)))
    rows, cols = np.mgrid[2:64:9, 3:64:9]
    pts = grid.to_world(cols.ravel(), rows.ravel())
    outside = np.hypot(pts[:, 0], pts[:, 1]) > 0.25  # not under the pillar
    direct = hidden_sky_fraction(world, pts[outside], n_directions=512)
    got = h[rows.ravel(), cols.ravel()][outside]
    assert direct.max() > 0.1, "some pixels must lie close to the pillar"
    assert np.max(np.abs(got - direct)) < 0.02, f"interpolated h off by {np.max(np.abs(got - direct)):.3f}"
    assert np.all(h >= -1e-12) and h.max() <= 1.0


@settings(max_examples=8)  # each example differentiates through u's own derivative: ~4x the point test
@given(d=scene)
def test_pillar_point_gradients_with_a_pixel_footprint_match_finite_differences(d):
    theta0 = theta_of(d)
    mdl = pillar("linear")
    _, sun, pose = unpack(jnp.asarray(theta0))
    points = pillar_shadow_samples(sun, pose, phase=d["phase"])
    axes = np.array([[0.011, 0.002, 0.0], [-0.003, 0.013, 0.0]])  # a skewed 1 cm pixel
    check_point_gradients(mdl, theta0, points, 1.5 * d["range_k"], pixel_axes=axes)


@pytest.mark.parametrize("profile", ["disk"])  # linear: the point property test above
def test_ground_map_gradient_with_footprint_and_sky_matches_finite_differences(profile):
    """Gradient of sum(W * map) (plan, with its hidden sky, fixed) vs central differences, with a
    penumbra about a pixel wide so that the footprint matters."""
    theta0 = np.array([0.006, 0.35, 150.0, 50.0, 0.1, -0.05, 0.0, 0.0, 0.0, 25.0])
    mdl = pillar(profile)
    params, sun, pose = unpack(jnp.asarray(theta0))
    grid = GroundGrid.around((-0.6, 1.6), 2.4, 64)
    plan = mdl.plan_grid(sun, pose, grid, range_k_max=0.009)
    assert plan.sky_hidden is not None and plan.sky_hidden.max() > 0.05
    weights = jnp.asarray(np.random.default_rng(3).standard_normal((64, 64)))

    def loss(theta):
        p, s, q = unpack(theta)
        return jnp.sum(weights * mdl.ground_map(p, s, q, grid, plan=plan))

    grad = np.asarray(jax.grad(loss)(jnp.asarray(theta0)))
    assert np.all(np.isfinite(grad))
    for i, name in enumerate(PARAM_NAMES):
        if name in ("z", "rot_x", "rot_y"):
            continue  # a pillar standing on the ground: checked in test_render_gradients
        e = np.zeros(10)
        e[i] = STEPS[i]
        fd = float(loss(jnp.asarray(theta0 + e)) - loss(jnp.asarray(theta0 - e))) / (2 * STEPS[i])
        assert abs(grad[i] - fd) <= 2e-3 * abs(fd) + 1e-5, f"{name}: grad {grad[i]:.8g} vs fd {fd:.8g}"
