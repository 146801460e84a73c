"""Gradients of the soft shadow renderer: autodiff against central finite differences (float64).

The discrete choices (silhouette, governing edge, hard shadow, penumbra band)
are made once in a plan and held fixed (tests/gradcheck.py), so the finite
differences see the same piecewise-smooth function that autodiff
differentiates. Points are taken inside the penumbra (alpha well inside
(0, 1)), away from the linear ramp's kinks; a point whose forward and backward
differences disagree sits on a kink of the piecewise formula (a switch of
governing edge) and is left out, but most points must remain.

Every differentiable parameter is checked: k, rho, sun azimuth and elevation,
pose translation x, y, z and rotation about x, y, z, for both expansion rules
and both profiles.
"""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from gradcheck import PARAM_NAMES, STEPS, check_point_gradients, unpack
from softshadow import GroundGrid, Pose, ShadowParams, SoftShadowModel, Sun
from softshadow.meshes import builtin_mesh

@functools.cache
def model(mesh: str, rule: str, profile: str) -> SoftShadowModel:
    return SoftShadowModel.from_mesh(builtin_mesh(mesh), rule=rule, profile=profile)


def ground_of(points_world: np.ndarray, light: np.ndarray) -> np.ndarray:
    """Project world points (N, 3) along the light onto z = 0 (N, 2); independent of the package."""
    lam = points_world[:, 2] / light[2]
    return points_world[:, :2] - lam[:, None] * light[:2]


def pillar_shadow_samples(sun: Sun, pose: Pose, height: float = 3.0, phase: float = 0.37) -> np.ndarray:
    """Receiver points (N, 3) on cross-sections of a pillar's shadow and around its tip.

    ``phase`` in [0, 1) shifts the sampling by a fraction of its spacing, so that
    points do not sit exactly on a hard-shadow boundary (not a generic point).
    """
    light = np.asarray(sun.light)
    rot = np.asarray(pose.rotation)
    axis_world = np.array([[0.0, 0.0, 0.0], [0.0, 0.0, height]]) @ rot.T + np.asarray(pose.position)
    base, tip = ground_of(axis_world, light)
    along = tip - base
    length = np.linalg.norm(along)
    along /= length
    perp = np.array([-along[1], along[0]])
    offsets = np.linspace(-0.33, 0.33, 265) + phase * 0.0025
    rows = [base + f * length * along + offsets[:, None] * perp for f in (0.2, 0.45, 0.7, 0.9)]
    rows += [tip + offsets[:, None] * along + o * perp for o in (-0.06, 0.013, 0.05)]
    xy = np.concatenate(rows)
    return np.c_[xy, np.zeros(len(xy))]


def ball_shadow_samples(sun: Sun, pose: Pose) -> np.ndarray:
    """Receiver points (N, 3) on rays from the ball's shadow centre outwards."""
    light = np.asarray(sun.light)
    centre_w = np.asarray(pose.rotation) @ [0.0, 0.0, 1.5] + np.asarray(pose.position)
    centre = ground_of(centre_w[None], light)[0]
    radii = np.linspace(0.2, 1.6, 200)
    dirs = [np.array([np.cos(a), np.sin(a)]) for a in np.linspace(0, 2 * np.pi, 7, endpoint=False)]
    xy = np.concatenate([centre + radii[:, None] * d for d in dirs])
    return np.c_[xy, np.zeros(len(xy))]


scene = st.fixed_dictionaries({
    "range_k": st.floats(0.01, 0.05),
    "rho": st.floats(0.05, 0.95),
    "azimuth": st.floats(0.0, 360.0),
    "elevation": st.floats(20.0, 70.0),
    "x": st.floats(-1.0, 1.0),
    "y": st.floats(-1.0, 1.0),
    "z": st.floats(0.0, 0.3),
    "rot_x": st.floats(-10.0, 10.0),
    "rot_y": st.floats(-10.0, 10.0),
    "rot_z": st.floats(-180.0, 180.0),
    "phase": st.floats(0.05, 0.95),
})


def theta_of(d: dict) -> np.ndarray:
    return np.array([d[name] for name in PARAM_NAMES], dtype=np.float64)


@pytest.mark.parametrize("rule", ["edge", "paper"])
@pytest.mark.parametrize("profile", ["linear", "disk"])
@given(d=scene)
def test_pillar_point_gradients_match_finite_differences(rule, profile, d):
    theta0 = theta_of(d)
    mdl = model("pillar", rule, profile)
    _, sun, pose = unpack(jnp.asarray(theta0))
    points = pillar_shadow_samples(sun, pose, phase=d["phase"])
    jac = check_point_gradients(mdl, theta0, points, 1.5 * d["range_k"])
    # The penumbra carries gradient for every parameter (none is silently dropped).
    for i, name in enumerate(PARAM_NAMES):
        assert np.max(np.abs(jac[:, i])) > 1e-6, f"{name}: zero gradient across the whole penumbra"


@pytest.mark.parametrize("rule,profile", [("edge", "linear"), ("paper", "disk")])
@given(d=scene)
def test_ball_point_gradients_match_finite_differences(rule, profile, d):
    theta0 = theta_of(d)
    mdl = model("ball", rule, profile)
    _, sun, pose = unpack(jnp.asarray(theta0))
    check_point_gradients(mdl, theta0, ball_shadow_samples(sun, pose), 1.5 * d["range_k"])


def test_shading_gradient_in_rho_is_alpha():
    """d shade / d rho = alpha exactly (shade = 1 - alpha (1 - rho)), everywhere."""
    theta0 = np.array([0.02, 0.4, 135.0, 40.0, 0.0, 0.0, 0.0, 0.0, 0.0, 20.0])
    mdl = model("pillar", "edge", "linear")
    params, sun, pose = unpack(jnp.asarray(theta0))
    points = pillar_shadow_samples(sun, pose)
    plan = mdl.plan_points(sun, pose, points, range_k_max=0.03)
    shade = np.asarray(mdl.at_points(params, sun, pose, points, plan=plan))
    grad_rho = np.asarray(jax.jacfwd(lambda r: mdl.at_points(ShadowParams(0.02, r), sun, pose, points,
                                                              plan=plan))(jnp.asarray(0.4)))
    alpha = (1.0 - shade) / (1.0 - 0.4)
    np.testing.assert_allclose(grad_rho, alpha, atol=1e-12)


@pytest.mark.parametrize("rule,profile", [("edge", "linear"), ("paper", "disk")])
def test_ground_map_gradient_matches_finite_differences(rule, profile):
    """Gradient of sum(W * ground map) for a fixed GridPlan vs central differences, all parameters."""
    theta0 = np.array([0.03, 0.35, 150.0, 50.0, 0.1, -0.05, 0.05, 2.0, -3.0, 25.0])
    mdl = model("pillar", rule, profile)
    params, sun, pose = unpack(jnp.asarray(theta0))
    grid = GroundGrid.around((-0.8, 2.2), 3.2, 96)
    plan = mdl.plan_grid(sun, pose, grid, range_k_max=0.045)
    weights = jnp.asarray(np.random.default_rng(3).standard_normal((96, 96)))

    def loss(theta):
        p, s, q = unpack(theta)
        return jnp.sum(weights * mdl.ground_map(p, s, q, grid, plan=plan))

    shading = np.asarray(mdl.ground_map(params, sun, pose, grid, plan=plan))
    assert np.sum((shading > 0.4) & (shading < 0.99)) > 100, "the map should show a penumbra"
    grad = np.asarray(jax.grad(loss)(jnp.asarray(theta0)))
    assert np.all(np.isfinite(grad))
    for i, name in enumerate(PARAM_NAMES):
        e = np.zeros(10)
        e[i] = STEPS[i]
        fd = float(loss(jnp.asarray(theta0 + e)) - loss(jnp.asarray(theta0 - e))) / (2 * STEPS[i])
        assert abs(grad[i] - fd) <= 2e-3 * abs(fd) + 1e-5, f"{name}: grad {grad[i]:.8g} vs fd {fd:.8g}"
        assert abs(fd) > 1e-4, f"{name}: the loss should depend on {name}"


@pytest.mark.parametrize("move", ["x", "azimuth", "elevation", "elevation_1deg"])
def test_held_plan_agrees_with_fresh_plan_for_moves_far_below_a_penumbra_width(move):
    """plan.py: a plan holds until the sun or pose moves by about a penumbra width.

    So rendering at theta0 + delta with the plan made at theta0 must give the
    values of a fresh plan at theta0 + delta when delta moves the shadow edge by
    a tenth of the penumbra width (what a fitter does between re-plans); in
    particular the ramp must stay monotone across the hard boundary.
    """
    mdl = model("pillar", "edge", "linear")
    params = ShadowParams(0.03, 0.2)
    sun0, pose0 = Sun(180.0, 45.0), Pose(rotation_deg=(0.0, 0.0, 30.0))
    # Shadow runs north; at y = 1.5 m the side edges' source points are 1.5 m up:
    # W = 2 k d = 2 * 0.03 * 1.5 / sin 45 ~ 0.127 m across the side edges.
    xs = np.linspace(-0.4, 0.4, 801) + 1.37e-4
    points = np.c_[xs, np.full_like(xs, 1.5), np.zeros_like(xs)]
    width = 2 * 0.03 * 1.5 / np.sin(np.radians(45.0))
    sun1, pose1 = {
        "x": (sun0, Pose(position=(width / 10, 0.0, 0.0), rotation_deg=(0.0, 0.0, 30.0))),
        # azimuth: the shadow direction turns about the base; at 1.5 m out, a tenth of W.
        "azimuth": (Sun(180.0 + np.degrees(width / 10 / 1.5), 45.0), pose0),
        # elevation changes the side edges' distance d (the ramp width), not the side lines;
        # 0.12 deg moves the tip (3 m / tan E) by a tenth of W.
        "elevation": (Sun(180.0, 45.0 + 0.12), pose0),
        # 1 deg moves the tip by 0.10 m, still less than any penumbra width here (W = 0.127 m at
        # the sides, 0.36 m at the tip), but the ground points now lie beside other segments of
        # the (21-segment) corner edges than the held plan's.
        "elevation_1deg": (Sun(180.0, 45.0 + 1.0), pose0),
    }[move]
    plan0 = mdl.plan_points(sun0, pose0, points, range_k_max=0.045)
    held = np.asarray(mdl.at_points(params, sun1, pose1, points, plan=plan0))
    fresh = np.asarray(mdl.at_points(params, sun1, pose1, points, range_k_max=0.045))
    i = int(np.argmax(np.abs(held - fresh)))
    worst = float(np.abs(held - fresh).max())
    assert worst < 0.02, (
        f"{move}: held plan gives {held[i]:.4f}, fresh plan {fresh[i]:.4f} at x = {xs[i]:.4f} m")
