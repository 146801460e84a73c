"""The float32 path: what the command line and the benchmarks run (the suite itself runs in float64).

Each check renders the same scene twice, in the session's float64 and inside a
``jax.enable_x64(False)`` scope (float32, as ``softshadow render`` and the
benchmarks do), and compares. The discrete plan is NumPy float64 in both, so
the two differ only by float32 rounding in the differentiable part: ground
points of a few metres carry about 1e-6 m of error, a small fraction of a
penumbra (k d ~ centimetres), so values agree to about 1e-4.
"""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from softshadow import GroundGrid, Pose, ShadowParams, SoftShadowModel, Sun, look_at_camera
from softshadow.meshes import builtin_mesh

# Stated tolerances (measured differences are quoted beside each use).
VALUE_TOL = 2e-3
GRAD_RTOL = 1e-2

SCENES = {
    "pillar": (Sun(160.0, 30.0), GroundGrid.around((-0.9, 2.4), 6.0, 64), (-0.9, 2.4)),
    "ball": (Sun(160.0, 45.0), GroundGrid.around((-0.9, 1.2), 3.0, 64), (-0.9, 1.2)),
}
PARAMS, POSE = ShadowParams(0.01, 0.3), Pose(position=(0.05, -0.03, 0.0), rotation_deg=(0.0, 0.0, 17.0))


@functools.cache
def model(name: str, profile: str = "linear") -> SoftShadowModel:
    return SoftShadowModel.from_mesh(builtin_mesh(name), profile=profile)


def renders(mdl: SoftShadowModel, sun: Sun, grid: GroundGrid, target) -> dict[str, np.ndarray]:
    """Ground map, values at scattered points and an oblique camera image, in the current precision."""
    points = grid.pixel_centres().reshape(-1, 3)[::3] + np.array([0.0123, -0.0071, 0.0])
    camera = look_at_camera((target[0] + 3.0, target[1] - 2.2, 2.0), (target[0], target[1], 0.0), 96, 72, 50.0)
    out = {"ground_map": mdl.ground_map(PARAMS, sun, POSE, grid),
           "points": mdl.at_points(PARAMS, sun, POSE, points),
           "camera": mdl.camera_image(PARAMS, sun, POSE, camera).shading}
    expected = jnp.result_type(float)
    for name, value in out.items():
        assert value.dtype == expected, f"{name}: {value.dtype}, expected {expected}"
    return {name: np.asarray(value, np.float64) for name, value in out.items()}


@pytest.mark.parametrize("name,profile", [("pillar", "linear"), ("ball", "disk")])
def test_float32_values_match_float64(name, profile):
    sun, grid, target = SCENES[name]
    mdl = model(name, profile)
    reference = renders(mdl, sun, grid, target)
    with jax.enable_x64(False):
        single = renders(mdl, sun, grid, target)
    assert jnp.result_type(float) == jnp.float64, "the float32 scope must not leak"
    for key, ref in reference.items():
        got = single[key]
        np.testing.assert_array_equal(np.isnan(got), np.isnan(ref))  # the same pixels see ground
        ok = ~np.isnan(ref)
        assert np.sum((ref[ok] > 0.35) & (ref[ok] < 0.95)) > 20, f"{key}: the view should hold a penumbra"
        diff = np.abs(got[ok] - ref[ok])
        # Measured: at most a few 1e-5 here.
        assert diff.max() <= VALUE_TOL, f"{key}: float32 differs by {diff.max():.2e} at worst"


def _ground_loss_grad(mdl, sun, grid):
    """jax.grad of sum(W * ground map) wrt (k, rho, sun, pose), plan fixed, in the current precision."""
    plan = mdl.plan_grid(sun, POSE, grid, range_k_max=0.015)
    weights = np.random.default_rng(5).uniform(0.5, 1.5, (grid.height, grid.width))

    def loss(params, s, pose):
        return jnp.sum(weights * mdl.ground_map(params, s, pose, grid, plan=plan))

    grads = jax.grad(loss, argnums=(0, 1, 2))(PARAMS, sun, POSE)
    leaves = jax.tree_util.tree_leaves(grads)
    assert all(leaf.dtype == jnp.result_type(float) for leaf in leaves)
    return np.concatenate([np.ravel(np.asarray(leaf, np.float64)) for leaf in leaves])


@pytest.mark.parametrize("name", ["pillar", "ball"])
def test_float32_gradients_are_finite_and_match_float64(name):
    sun, grid, _ = SCENES[name]
    mdl = model(name)
    reference = _ground_loss_grad(mdl, sun, grid)
    with jax.enable_x64(False):
        single = _ground_loss_grad(mdl, sun, grid)
    assert np.all(np.isfinite(single))
    # Every gradient the float64 path sees is there in float32 too, to 1 % of its own size or
    # of the largest component (measured: well under 1e-3 relative).
    scale = np.abs(reference).max()
    assert np.all(np.abs(single - reference) <= GRAD_RTOL * np.maximum(np.abs(reference), 0.01 * scale)), (
        f"float32 {single} vs float64 {reference}")
