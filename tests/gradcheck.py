"""Autodiff against central finite differences (float64), shared by the gradient tests.

The renderer's discrete choices are made once in a plan and held fixed, so the
finite differences see the same piecewise-smooth function that autodiff
differentiates. A point whose forward and backward differences disagree sits
on a kink of the piecewise formula (a ramp end, a switch of governing edge)
and is left out, but most points must remain.
"""

from __future__ import annotations

import dataclasses

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from softshadow import Pose, ShadowParams, Sun
from softshadow.internal import concatenate_plans

PARAM_NAMES = ("range_k", "rho", "azimuth", "elevation", "x", "y", "z", "rot_x", "rot_y", "rot_z")
# Central-difference steps: small against the scales (k >= 0.01, penumbra widths >= ~5 mm).
STEPS = np.array([1e-7, 1e-6, 1e-6, 1e-6, 1e-7, 1e-7, 1e-7, 1e-6, 1e-6, 1e-6])
# One edge count and at least one point count for every plan: a property test's examples (and the
# hard cases) then share one compiled evaluation per rule and profile instead of recompiling
# whenever a count crosses a power of two. Point sets of up to POINT_PAD points share one shape;
# larger ones take the plan's own power of two (every padded point is evaluated: no larger).
EDGE_PAD = 256
POINT_PAD = 512
PAIR_PAD, CROSS_PAD = 4096, 512  # the wedge rule's pairs and crossings


def unpack(theta):
    """(ShadowParams, Sun, Pose) from the parameter vector (10,) in PARAM_NAMES order."""
    return (ShadowParams(theta[0], theta[1]), Sun(theta[2], theta[3]),
            Pose(position=theta[4:7], rotation_deg=theta[7:10]))


def fixed_shape_plan(mdl, sun, pose, points, range_k_max, pixel_axes=None):
    """plan_points padded to EDGE_PAD edges and POINT_PAD points (same values, one compiled shape);
    pixel_axes: the pixel footprints the plan holds the pixel means for."""
    plan = mdl.plan_points(sun, pose, points, range_k_max=range_k_max, pixel_axes=pixel_axes)
    n_edges = int(np.asarray(plan.edges.outward_sign).shape[0])
    plan = concatenate_plans([plan], [len(points)], pad_to=max(POINT_PAD, int(plan.edge_id.shape[0])),
                             edge_pad_to=max(EDGE_PAD, n_edges), pairs_to=PAIR_PAD, cross_to=CROSS_PAD)
    # ``active`` as a JAX array: at_points evaluates every padded point (as for a traced plan) rather
    # than the band's, whose count would set the compiled shape.
    return eqx.tree_at(lambda q: q.active, plan, jnp.asarray(plan.active))


def check_point_gradients(mdl, theta0: np.ndarray, points: np.ndarray, range_k_max: float,
                          min_points: int = 8, keep=None, params=None,
                          steps=None, smooth_fraction: float = 0.85, pixel_axes=None):
    """Autodiff Jacobian (N, 10) of shading at points vs central differences, plan held fixed.

    keep: (N,) bool, the points to compare (default: inside the penumbra, alpha in
    (0.05, 0.95)); params: indices into PARAM_NAMES to check; steps (10,): the central
    difference steps (default STEPS; smaller for a narrow penumbra). Returns the Jacobian
    rows of the kept points. pixel_axes: each point's pixel footprint (``at_points``), None for
    point sampling.
    """
    theta0 = np.asarray(theta0, np.float64)
    sun, pose = unpack(jnp.asarray(theta0))[1:]
    plan = fixed_shape_plan(mdl, sun, pose, points, range_k_max, pixel_axes)

    def shading(theta):
        p, s, q = unpack(theta)
        return mdl.at_points(p, s, q, points, plan=plan, pixel_axes=pixel_axes)

    base = np.asarray(shading(jnp.asarray(theta0)))
    if keep is None:
        alpha = (1.0 - base) / (1.0 - theta0[1])
        keep = (alpha > 0.05) & (alpha < 0.95)
    assert keep.sum() >= min_points, (
        f"only {keep.sum()} sample points in the penumbra; the sampling misses the shadow edge")
    jac = np.asarray(jax.jacfwd(shading)(jnp.asarray(theta0)))
    assert np.all(np.isfinite(jac)), "non-finite autodiff gradient"
    steps = STEPS if steps is None else np.asarray(steps, np.float64)
    for i in range(len(PARAM_NAMES)) if params is None else params:
        name = PARAM_NAMES[i]
        e = np.zeros(10)
        e[i] = steps[i]
        plus = np.asarray(shading(jnp.asarray(theta0 + e)))
        minus = np.asarray(shading(jnp.asarray(theta0 - e)))
        forward, backward = (plus - base) / steps[i], (base - minus) / steps[i]
        central = 0.5 * (forward + backward)
        scale = max(float(np.max(np.abs(central[keep]))), 1e-3)
        # One-sided differences disagree only at a kink (a ramp end, a switch of edge).
        smooth = keep & (np.abs(forward - backward) <= 1e-4 * scale)
        assert smooth.sum() >= smooth_fraction * keep.sum(), (
            f"{name}: kinks or jumps at {keep.sum() - smooth.sum()} of {keep.sum()} penumbra points")
        err = np.abs(jac[smooth, i] - central[smooth])
        worst = int(np.argmax(err)) if len(err) else 0
        assert np.all(err <= 1e-4 * scale + 1e-7), (
            f"{name}: autodiff {jac[smooth, i][worst]:.6g} vs finite difference "
            f"{central[smooth][worst]:.6g} (scale {scale:.3g})")
    return jac[keep]


def fixed_shape_grid_plan(mdl, sun, pose, grid, range_k_max):
    """plan_grid with every pixel's slot in the band and EDGE_PAD edges (same values, one
    compiled shape per grid size, whatever the band's size)."""
    plan = mdl.plan_grid(sun, pose, grid, range_k_max=range_k_max)
    size = grid.height * grid.width
    index = np.full(size, size, np.int32)
    index[:plan.n_band] = np.asarray(plan.band_index)[:plan.n_band]
    n_edges = int(np.asarray(plan.plan.edges.outward_sign).shape[0])
    points = concatenate_plans([plan.plan], [plan.n_band], pad_to=size, edge_pad_to=max(EDGE_PAD, n_edges),
                               pairs_to=PAIR_PAD, cross_to=CROSS_PAD)
    return dataclasses.replace(plan, band_index=index, plan=points)


def k_zero_and_near_maps(mdl, sun, pose, grid):
    """The ground maps (H, W) at k = 0 and k = 1e-7 (rho 0.3), each on a plan of the whole grid
    (``fixed_shape_grid_plan``: one compiled evaluation for both)."""
    from softshadow import ShadowParams
    return tuple(np.asarray(mdl.ground_map(ShadowParams(k, 0.3), sun, pose, grid,
                                           plan=fixed_shape_grid_plan(mdl, sun, pose, grid, k))) for k in (0.0, 1e-7))


def assert_jacobian_matches_central_differences(fn, x: np.ndarray, jac: np.ndarray, h: float = 1e-6) -> None:
    """Each column of ``jac`` (n, p), the Jacobian of ``fn`` (p,) -> (n,) at ``x``, against central
    differences of step ``h``, to 2e-6 of the column's largest difference (at least 2e-6)."""
    for i in range(len(x)):
        e = np.zeros(len(x))
        e[i] = h
        fd = (np.asarray(fn(x + e)) - np.asarray(fn(x - e))) / (2 * h)
        np.testing.assert_allclose(jac[:, i], fd, atol=2e-6 * max(1.0, np.abs(fd).max()), err_msg=f"column {i}")
