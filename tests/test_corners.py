"""Corners of the shadow's outline: the light's mass behind the corner's wedge
(docs/renderer.md, "Pixel footprint, hidden sky and corners").

- ``corner_mass`` against a Monte Carlo mass of the uniform disk and of the linear-ramp
  ("Archimedes") light over random convex and concave wedges; its limits (one line, two
  collinear lines, the apex); its gradients against finite differences (hypothesis, float64).
- ``corner_alpha`` at a plate's convex and concave corner 1 m above the ground against a brute
  force over the sun's directions (rays to the plate's plane), for both profiles, with and
  without the corner; two collinear edges give exactly the single edge; finite values and
  gradients at the hard cases (at the apex, on an edge, k = 0 and 1e-12, a zero-length neighbour,
  a 5-degree corner); the float32 path.
- The pillar's tip in a ground map against a brute force over the sun's disk (ray casting).
"""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
import numpy as np
import pytest
import trimesh
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from softshadow import GroundGrid, Pose, ShadowParams, SoftShadowModel, Sun
from softshadow.meshes import builtin_mesh
from softshadow.penumbra import corner_alpha, corner_mass, edge_alpha, profile_alpha

LIGHT = np.array([0.25, 0.55, -0.8])
LIGHT = LIGHT / np.linalg.norm(LIGHT)
HEIGHT = 1.0
K = 0.02


def light_samples(profile: str, n: int, seed: int = 0) -> np.ndarray:
    """Points (n, 2) of the unit disk under the light's density: uniform (disk) or
    1 / (2 pi sqrt(1 - r^2)) (linear: its edge profile is the linear ramp)."""
    rng = np.random.default_rng(seed)
    u = rng.random(n)
    r = np.sqrt(u) if profile == "disk" else np.sqrt(1.0 - (1.0 - u) ** 2)
    t = 2.0 * np.pi * rng.random(n)
    return np.c_[r * np.cos(t), r * np.sin(t)]


@pytest.mark.parametrize("profile", ["disk", "linear"])
def test_corner_mass_matches_a_monte_carlo_mass_of_the_light_over_the_wedge(profile):
    p = light_samples(profile, 400_000)
    rng = np.random.default_rng(1)
    worst = 0.0
    for trial in range(40):
        a1, a2 = rng.uniform(0.0, 2.0 * np.pi, 2)
        n1, n2 = np.array([np.cos(a1), np.sin(a1)]), np.array([np.cos(a2), np.sin(a2)])
        u1, u2 = rng.uniform(-1.3, 1.3, 2)
        convex = trial % 2 == 0
        in1, in2 = p @ n1 < -u1, p @ n2 < -u2  # the occluder's side of each line
        brute = np.mean(in1 & in2) if convex else np.mean(in1 | in2)
        got = float(corner_mass(u1, u2, n1 @ n2, abs(n1[0] * n2[1] - n1[1] * n2[0]), convex, profile))
        worst = max(worst, abs(got - brute))
    assert worst < 3e-3, f"wedge mass off by {worst:.2e}"  # Monte Carlo noise ~1e-3


@pytest.mark.parametrize("profile", ["disk", "linear"])
def test_corner_mass_limits(profile):
    u = jnp.linspace(-1.6, 1.6, 33) + 0.003
    half = profile_alpha(u, profile)
    c, s = np.cos(1.2), np.sin(1.2)
    # A line far inside the other's half-plane (convex) or far outside it (concave): one edge.
    np.testing.assert_allclose(corner_mass(u, -5.0, c, s, True, profile), half, atol=1e-12)
    np.testing.assert_allclose(corner_mass(u, 5.0, c, s, False, profile), half, atol=1e-12)
    # Two collinear lines are one line, convex or concave; nearly collinear, nearly so.
    for convex in (True, False):
        np.testing.assert_allclose(corner_mass(u, u, 1.0, 0.0, convex, profile), half, atol=1e-12)
    np.testing.assert_allclose(corner_mass(u, u + 1e-7, np.cos(1e-7), 1e-7, True, profile), half, atol=1e-6)
    # Symmetric in the two lines.
    v = jnp.flip(u)
    np.testing.assert_allclose(corner_mass(u, v, c, s, True, profile), corner_mass(v, u, c, s, True, profile),
                               atol=1e-12)
    # At the apex: the wedge's angle over 2 pi (90 degrees: a quarter), and just beside it.
    assert float(corner_mass(0.0, 0.0, 0.0, 1.0, True, profile)) == pytest.approx(0.25, abs=1e-12)
    assert float(corner_mass(0.0, 0.0, 0.0, 1.0, False, profile)) == pytest.approx(0.75, abs=1e-12)
    assert float(corner_mass(1e-4, -2e-4, 0.0, 1.0, True, profile)) == pytest.approx(0.25, abs=1e-3)
    sharp = 5.0 * np.pi / 180.0  # normals 175 degrees apart: a 5-degree spike
    assert float(corner_mass(0.0, 0.0, -np.cos(sharp), np.sin(sharp), True, profile)) == pytest.approx(
        sharp / (2.0 * np.pi), abs=1e-9)


@functools.partial(jax.jit, static_argnames=("convex", "profile"))
def _mass_and_grad(x, convex, profile):
    f = lambda v: corner_mass(v[0], v[1], jnp.cos(v[2]), jnp.abs(jnp.sin(v[2])), convex, profile)
    return jax.vmap(jax.value_and_grad(f))(x)


@pytest.mark.parametrize("profile", ["disk", "linear"])
@pytest.mark.parametrize("convex", [True, False])
@given(u1=st.floats(-1.4, 1.4), u2=st.floats(-1.4, 1.4), angle=st.floats(0.1, 3.04))
def test_corner_mass_gradients_match_finite_differences(profile, convex, u1, u2, angle):
    # Generic points: away from the ramp's ends (the linear profile's kinks) and the apex.
    assume(min(abs(abs(u1) - 1.0), abs(abs(u2) - 1.0)) > 1e-3 and abs(u1) + abs(u2) > 1e-3)
    x0 = np.array([u1, u2, angle])
    eps = 1e-7
    rows = np.vstack([x0, x0 + eps * np.eye(3), x0 - eps * np.eye(3)])
    values, grads = (np.asarray(a) for a in _mass_and_grad(jnp.asarray(rows), convex, profile))
    assert np.all(np.isfinite(grads))
    fd = (values[1:4] - values[4:7]) / (2 * eps)
    for i in range(3):
        assert abs(grads[0, i] - fd[i]) <= 2e-5 + 1e-4 * abs(fd[i]), (
            f"d/d{('u1', 'u2', 'angle')[i]}: {grads[0, i]} vs {fd[i]}")


# -- a plate's corner 1 m above the ground: corner_alpha against a brute force -------------------

def plate_edges(concave: bool, angle_deg: float = 90.0, neighbour_length: float = 2.0):
    """Two edges meeting at the origin at HEIGHT: edge 0 along -x to the apex, edge 1 from the apex
    at ``angle_deg`` from edge 0's line. Convex: the plate is the wedge between them (below y = 0);
    concave: everything else. Returns (edge vertices (2, 2, 3), outward signs (2,), neighbours
    (2, 2), occluded(xy) in the plate's plane)."""
    a = np.radians(angle_deg)
    apex = np.array([0.0, 0.0, HEIGHT])
    far0 = np.array([-2.0, 0.0, HEIGHT])
    d1 = np.array([-np.cos(a), -np.sin(a), 0.0])
    far1 = apex + neighbour_length * d1
    ev = np.stack([[far0, apex], [apex, far1]])

    def occluded(xy):
        below0 = xy[..., 1] < 0.0
        n1 = np.array([np.sin(a), -np.cos(a)])  # edge 1's normal pointing away from the wedge
        inside1 = xy[..., 0] * n1[0] + xy[..., 1] * n1[1] < 0.0
        wedge = below0 & inside1
        return ~wedge if concave else wedge

    # Outward: towards the lit side, off the plate.
    out0 = np.array([0.0, -1.0, 0.0]) if concave else np.array([0.0, 1.0, 0.0])
    n1 = np.array([np.sin(a), -np.cos(a), 0.0])
    out1 = -n1 if concave else n1
    signs = []
    for (p, q), out in zip(ev, (out0, out1)):
        t = (q - p) / max(np.linalg.norm(q - p), 1e-12)
        signs.append(1.0 if np.dot(np.cross(t, LIGHT), out) > 0 else -1.0)
    return ev, np.array(signs), np.array([[-1, 1], [0, -1]], np.int32), occluded


def ground_of_apex() -> np.ndarray:
    return np.array([0.0, 0.0]) + HEIGHT * LIGHT[:2] / -LIGHT[2]


def brute_alpha(points: np.ndarray, occluded, profile: str, k: float, n: int = 40_000) -> np.ndarray:
    """Occluded fraction of the light (angular radius atan k, in the gnomonic plane) at ground
    points (N, 3): rays to the plate's plane z = HEIGHT."""
    e1 = np.cross(LIGHT, [0.0, 0.0, 1.0])
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(LIGHT, e1)
    d = light_samples(profile, n, seed=7) * k
    dirs = -LIGHT[None] + d[:, :1] * e1[None] + d[:, 1:] * e2[None]
    out = []
    for p in points:
        s = (HEIGHT - p[2]) / dirs[:, 2]
        hit = p[None, :2] + s[:, None] * dirs[:, :2]
        out.append(np.mean(occluded(hit)))
    return np.array(out)


def corner_points(n_side: int = 9, reach: float = 2.5) -> np.ndarray:
    """A grid of ground points (n_side^2, 3) within ``reach`` penumbra half-widths of the apex's shadow,
    offset so that none lies exactly on an edge's shadow."""
    half_width = K * HEIGHT / -LIGHT[2]
    s = np.linspace(-reach, reach, n_side) * half_width + 0.1234 * half_width / n_side
    xy = ground_of_apex() + np.stack(np.meshgrid(s, s), -1).reshape(-1, 2)
    return np.c_[xy, np.zeros(len(xy))]


@functools.partial(jax.jit, static_argnames=("profile", "corners"))
def plate_eval(theta, points, ev, signs, inside, neighbours, axes, profile, corners=True):
    """Alpha at points (n, 3) + (theta[3], theta[4], 0) under LIGHT + (theta[1], theta[2], 0) with
    k = theta[0]; both edges are candidates; axes: a pixel footprint (2, 3) or None."""
    light = jnp.asarray(LIGHT, theta.dtype) + jnp.stack([theta[1], theta[2], jnp.zeros_like(theta[0])])
    light = light / jnp.linalg.norm(light)
    pts = points + jnp.stack([theta[3], theta[4], jnp.zeros_like(theta[0])])[None]
    ids = jnp.tile(jnp.array([[0, 1]], jnp.int32), (points.shape[0], 1))
    args = (pts, ids, ev, signs, light, theta[0], inside)
    if corners:
        return corner_alpha(*args, neighbours, profile=profile, pixel_axes=axes)
    return edge_alpha(*args, profile=profile, pixel_axes=axes)


def plate_inside(points, occluded):
    """The hard shadow at ground points: the plate's occlusion of the sun's centre."""
    return occluded(points[:, :2] + (HEIGHT - points[:, 2:3]) * (LIGHT[None, :2] / LIGHT[2])).astype(float)


def plate_alpha(points, ev, signs, neighbours, occluded, profile, k=K, corners=True, pixel_axes=None,
                dtype=jnp.float64):
    """corner_alpha (or edge_alpha without corners) at points, both edges as candidates."""
    theta = jnp.asarray([k, 0.0, 0.0, 0.0, 0.0], dtype)
    return plate_eval(theta, jnp.asarray(points, dtype), jnp.asarray(ev, dtype), jnp.asarray(signs, dtype),
                      jnp.asarray(plate_inside(points, occluded), dtype), jnp.asarray(neighbours, jnp.int32),
                      None if pixel_axes is None else jnp.asarray(pixel_axes, dtype), profile, corners)


@pytest.mark.parametrize("profile", ["disk", "linear"])
@pytest.mark.parametrize("concave", [False, True])
@pytest.mark.parametrize("angle", [90.0, 50.0])
def test_plate_corner_matches_a_brute_force_over_the_sun(profile, concave, angle):
    ev, signs, nbr, occluded = plate_edges(concave, angle)
    pts = corner_points()
    brute = brute_alpha(pts, occluded, profile, K)
    new = np.asarray(plate_alpha(pts, ev, signs, nbr, occluded, profile))
    old = np.asarray(plate_alpha(pts, ev, signs, nbr, occluded, profile, corners=False))
    err_new, err_old = np.abs(new - brute).max(), np.abs(old - brute).max()
    # The edge rule's u is the gnomonic distance to first order in k (k = 0.02 here).
    assert err_new < 0.02, f"corner alpha off by {err_new:.3f} (single edge: {err_old:.3f})"
    assert err_old > 0.08  # the single edge is far off at a corner: the test sees corners


@pytest.mark.parametrize("profile", ["disk", "linear"])
def test_two_collinear_edges_are_the_single_edge(profile):
    """A straight outline split at a vertex (a tessellated straight edge) is unchanged, with and
    without a pixel footprint."""
    ev, signs, nbr, occluded = plate_edges(False, 180.0)  # edge 1 continues edge 0 along +x
    whole = np.stack([[ev[0, 0], ev[1, 1]]])
    pts = corner_points()
    axes = jnp.asarray([[0.004, 0.001, 0.0], [-0.001, 0.005, 0.0]])
    for ax in (None, axes):
        split = np.asarray(plate_alpha(pts, ev, signs, nbr, occluded, profile, pixel_axes=ax))
        single = np.asarray(plate_alpha(pts, np.concatenate([whole, whole]), signs, np.full((2, 2), -1),
                                        occluded, profile, pixel_axes=ax))
        assert 0.05 < split.mean() < 0.95
        np.testing.assert_allclose(split, single, atol=1e-9)


@pytest.mark.parametrize("profile", ["disk", "linear"])
def test_corner_alpha_is_finite_at_the_hard_cases(profile):
    apex = np.r_[ground_of_apex(), 0.0]
    half_width = K * HEIGHT / -LIGHT[2]
    cases = [
        (plate_edges(False), apex, K),                                      # at the apex's shadow
        (plate_edges(True), apex, K),                                       # concave apex
        (plate_edges(False), apex + [-0.3 * half_width, 0.0, 0.0], K),      # on edge 0's shadow
        (plate_edges(False), apex + [0.01, -0.02, 0.0], 0.0),               # k = 0
        (plate_edges(False), apex + [0.01, -0.02, 0.0], 1e-12),             # k = 1e-12
        (plate_edges(False, 90.0, 0.0), apex + [0.2 * half_width, 0.1 * half_width, 0.0], K),  # zero-length
        (plate_edges(False, 5.0), apex + [-0.5 * half_width, -0.02 * half_width, 0.0], K),     # 5-degree spike
        (plate_edges(False, 180.0), apex, K),                               # collinear, at the vertex
    ]
    value_and_grad = jax.jit(jax.value_and_grad(lambda th, *a: plate_eval(th, *a, profile=profile)[0]))
    for (ev, signs, nbr, occluded), p, k in cases:
        p = np.asarray(p, float)[None]
        value, grad = value_and_grad(jnp.array([k, 0.0, 0.0, 0.0, 0.0]), jnp.asarray(p), jnp.asarray(ev),
                                     jnp.asarray(signs), jnp.asarray(plate_inside(p, occluded)),
                                     jnp.asarray(nbr), None)
        assert np.isfinite(float(value)) and 0.0 <= float(value) <= 1.0
        assert np.all(np.isfinite(np.asarray(grad))), (p, k, grad)
    # Values: at the apex's shadow the wedge's angle as the sun sees it (a 90-degree corner seen
    # obliquely: 0.277 convex, 0.723 concave), as the brute force; k = 0 is the hard shadow.
    for concave in (False, True):
        ev, signs, nbr, occ = plate_edges(concave)
        got = float(plate_alpha(apex[None], ev, signs, nbr, occ, profile)[0])
        assert got == pytest.approx(brute_alpha(apex[None], occ, profile, K)[0], abs=0.005)
    pts = corner_points()
    ev, signs, nbr, occ = plate_edges(False)
    hard = occ(pts[:, :2] + HEIGHT * (LIGHT[None, :2] / LIGHT[2]))
    np.testing.assert_array_equal(np.asarray(plate_alpha(pts, ev, signs, nbr, occ, profile, k=0.0)),
                                  hard.astype(float))


@settings(max_examples=15, deadline=None)
@given(dx=st.floats(-2.0, 2.0), dy=st.floats(-2.0, 2.0), k=st.floats(0.005, 0.05),
       tilt=st.floats(-0.1, 0.1), angle=st.floats(30.0, 150.0), concave=st.booleans(),
       profile=st.sampled_from(["disk", "linear"]))
def test_corner_alpha_gradients_match_finite_differences(dx, dy, k, tilt, angle, concave, profile):
    """d alpha / d (k, light, point) near the corner, float64, plan (candidates) fixed."""
    assume(min(abs(dx), abs(dy)) > 1e-3)  # generic points: not on an edge's shadow nor at the apex
    ev, signs, nbr, occluded = plate_edges(concave, angle)
    half_width = k * HEIGHT / -LIGHT[2]
    p0 = np.r_[ground_of_apex() + half_width * np.array([dx, dy]), 0.0][None]
    args = (jnp.asarray(p0), jnp.asarray(ev), jnp.asarray(signs), jnp.asarray(plate_inside(p0, occluded)),
            jnp.asarray(nbr), jnp.asarray([[0.3, 0.05, 0.0], [-0.02, 0.4, 0.0]]) * half_width)
    theta0 = np.array([k, tilt * 0.01, 0.0, 0.0, 0.0])
    steps = np.array([1e-7, 1e-7, 1e-7, 1e-7 * half_width / K, 1e-7 * half_width / K])
    rows = np.vstack([theta0, theta0 + np.diag(steps), theta0 - np.diag(steps)])
    values = np.asarray(_plate_rows(jnp.asarray(rows), *args, profile=profile))
    assume(0.02 < values[0] < 0.98)
    grad = np.asarray(_plate_grad(jnp.asarray(theta0), *args, profile=profile))
    fd = (values[1:6] - values[6:11]) / (2 * steps)
    for i in range(5):
        assert abs(grad[i] - fd[i]) <= 1e-4 * abs(fd[i]) + 1e-3 * (1.0 / half_width if i >= 3 else 1.0), (
            f"parameter {i}: {grad[i]} vs {fd[i]}")


@functools.partial(jax.jit, static_argnames="profile")
def _plate_rows(rows, *args, profile):
    return jax.vmap(lambda th: plate_eval(th, *args, profile=profile)[0])(rows)


@functools.partial(jax.jit, static_argnames="profile")
def _plate_grad(theta, *args, profile):
    return jax.grad(lambda th: plate_eval(th, *args, profile=profile)[0])(theta)


def test_corner_alpha_float32_matches_float64():
    pts = corner_points()
    for concave in (False, True):
        ev, signs, nbr, occ = plate_edges(concave, 70.0)
        for profile in ("disk", "linear"):
            ref = np.asarray(plate_alpha(pts, ev, signs, nbr, occ, profile))
            with jax.enable_x64(False):
                single = np.asarray(plate_alpha(pts, ev, signs, nbr, occ, profile, dtype=jnp.float32,
                                                pixel_axes=None))
            assert single.dtype == np.float32
            assert np.max(np.abs(single - ref)) < 2e-3


# -- the pillar's tip in a ground map --------------------------------------------------------------

def test_pillar_tip_in_a_ground_map_against_ray_casting():
    """Point-sampled map of the pillar's tip (footprint and sky off) against the occluded fraction
    of the sun's disk by ray casting (trimesh): the corners' error falls several-fold."""
    sun, pose, params = Sun(200.0, 40.0), Pose(rotation_deg=(0.0, 0.0, 7.0)), ShadowParams(0.02, 0.0)
    mesh = builtin_mesh("pillar")
    model = SoftShadowModel.from_mesh(mesh, profile="disk", footprint=False, hidden_sky=False, corners=True)
    light = np.asarray(sun.light)
    world = mesh.copy()
    world.apply_transform(trimesh.transformations.rotation_matrix(np.radians(7.0), (0, 0, 1)))
    top = world.vertices[world.vertices[:, 2] > 2.9]
    tip = (top[:, :2] + top[:, 2:3] * (-light[None, :2] / light[2])).mean(0)
    grid = GroundGrid.around(tuple(tip), 0.5, 40)
    new = 1.0 - np.asarray(model.ground_map(params, sun, pose, grid))
    old = 1.0 - np.asarray(model.with_options(corners=False).ground_map(params, sun, pose, grid))
    band = (new > 0.02) & (new < 0.98) | (old > 0.02) & (old < 0.98)
    rows, cols = np.nonzero(band)
    pts = grid.to_world(cols, rows)
    e1 = np.cross(light, [0.0, 0.0, 1.0])
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(light, e1)
    d = light_samples("disk", 1500, seed=3) * params.range_k
    dirs = -light[None] + d[:, :1] * e1[None] + d[:, 1:] * e2[None]
    dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
    origins = np.repeat(pts, len(dirs), axis=0)
    hit = world.ray.intersects_any(origins, np.tile(dirs, (len(pts), 1))).reshape(len(pts), -1)
    brute = hit.mean(axis=1)
    err_new = np.sqrt(np.mean((new[rows, cols] - brute) ** 2))
    err_old = np.sqrt(np.mean((old[rows, cols] - brute) ** 2))
    assert len(pts) > 100
    assert err_new < 0.02 and err_new < 0.5 * err_old, f"RMS {err_new:.4f} (without corners {err_old:.4f})"
