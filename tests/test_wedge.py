"""The ``wedge`` rule (softshadow.wedge, softshadow.wedge_plan): the fraction of the sun's disk the
mesh hides, against an independent ray caster (data_synth.sun_visibility, 64 x 64 strata over the
disk), on the scenes where an edge-based ramp goes wrong: parts of the mesh overlapping in the
sun's view (depth complexity 2), a gap narrower than the penumbra, corners, a real mesh; receivers
on the ground and anywhere (the light-space path); and the agreement with the ``edge`` rule on a
lone straight edge.
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

from data_synth import SunSky, sun_visibility
from gradcheck import (PARAM_NAMES, STEPS, check_point_gradients, fixed_shape_grid_plan,
                       k_zero_and_near_maps, unpack)
from softshadow import GroundGrid, Pose, ShadowParams, SoftShadowModel, Sun
from softshadow.internal import concatenate_plans
from softshadow.meshes import builtin_mesh

point_model = functools.partial(SoftShadowModel.from_mesh, footprint=False, hidden_sky=False)


def slab(size, centre, height, angle_deg=0.0, thickness=0.02) -> trimesh.Trimesh:
    """A thin horizontal box (size (2,) metres) centred at centre (2,), its top at ``height``,
    turned by angle_deg about z."""
    box = trimesh.creation.box(extents=(size[0], size[1], thickness))
    box.apply_transform(trimesh.transformations.rotation_matrix(np.radians(angle_deg), [0, 0, 1]))
    box.apply_translation([centre[0], centre[1], height - thickness / 2])
    return box


def overlapping_slabs() -> trimesh.Trimesh:
    """Two slabs at 1.0 and 1.4 m whose shadows overlap partly (the higher one turned 25 deg)."""
    return trimesh.util.concatenate([slab((0.8, 0.6), (0.0, 0.0), 1.0), slab((0.7, 0.5), (0.35, 0.25), 1.4, 25.0)])


def boxes_with_gap(gap=0.01) -> trimesh.Trimesh:
    """Two 1 m tall boxes side by side with a gap of ``gap`` metres between them."""
    left = trimesh.creation.box(extents=(0.3, 0.4, 1.0))
    left.apply_translation([-0.15 - gap / 2, 0.0, 0.5])
    right = trimesh.creation.box(extents=(0.3, 0.4, 1.0))
    right.apply_translation([0.15 + gap / 2, 0.0, 0.5])
    return trimesh.util.concatenate([left, right])


def truth_alpha(mesh: trimesh.Trimesh, points: np.ndarray, az: float, el: float, radius_deg: float,
                n_samples: int = 4096):
    """1 - the visible fraction of a uniform sun disk, 64 x 64 strata by default (data_synth)."""
    sky = SunSky(az, el, radius_deg)
    normals = np.tile([0.0, 0.0, 1.0], (len(points), 1))
    return 1.0 - sun_visibility(mesh, points, normals, sky, n_samples=n_samples)


def ground_band(mesh, az, el, radius_deg, n=400, seed=0, extent=None):
    """Ground points (n, 3) where the truth is strictly between 0 and 1 (the penumbra)."""
    rng = np.random.default_rng(seed)
    v = np.asarray(mesh.vertices)
    light = -np.array([np.sin(np.radians(az)) * np.cos(np.radians(el)),
                       np.cos(np.radians(az)) * np.cos(np.radians(el)), np.sin(np.radians(el))])
    shadow = v[:, :2] - (v[:, 2] / light[2])[:, None] * light[:2]
    lo = np.minimum(shadow.min(0), v[:, :2].min(0)) - 0.2
    hi = np.maximum(shadow.max(0), v[:, :2].max(0)) + 0.2
    pts = np.c_[rng.uniform(lo, hi, (20 * n, 2)), np.zeros(20 * n)]
    # A coarse pass (16 x 16 strata) finds the candidates in the penumbra; only they get the fine one.
    coarse = truth_alpha(mesh, pts, az, el, radius_deg, n_samples=256)
    pts = pts[(coarse > 0.0) & (coarse < 1.0)][:2 * n]
    alpha = truth_alpha(mesh, pts, az, el, radius_deg)
    keep = np.flatnonzero((alpha > 0.02) & (alpha < 0.98))[:n]
    return pts[keep], alpha[keep]


@pytest.mark.parametrize("scene", ["slabs", "gap", "pillar", "knot"])
def test_ground_points_match_ray_casting(scene):
    """Penumbra points of hard scenes: within the truth's own quadrature error (1/64 strata)."""
    mesh, az, el, radius = {
        "slabs": (overlapping_slabs(), 200.0, 55.0, 1.5),
        "gap": (boxes_with_gap(0.01), 180.0, 50.0, 1.0),
        "pillar": (builtin_mesh("pillar"), 210.0, 35.0, 0.8),
        # The built-in knot decimated: a tube crossing itself in the sun's view.
        "knot": (builtin_mesh("dragon").simplify_quadric_decimation(face_count=2000), 160.0, 40.0, 1.0),
    }[scene]
    points, alpha = ground_band(mesh, az, el, radius)
    assert len(points) > 100
    mdl = point_model(mesh, rule="wedge", profile="disk")
    k = np.tan(np.radians(radius))
    got = 1.0 - np.asarray(mdl.at_points(ShadowParams(k, 0.0), Sun(az, el), Pose(), points))
    err = np.abs(got - alpha)
    assert np.sqrt(np.mean(err ** 2)) < 0.004, f"RMS {np.sqrt(np.mean(err ** 2)):.4f}"
    assert err.max() < 0.02, f"worst {err.max():.4f} at {points[np.argmax(err)]}"


def test_gap_narrower_than_the_penumbra_lets_light_through():
    """Behind a 1 cm gap under a 1-degree sun (penumbra ~3.5 cm) the umbra is lit in part; the
    edge rule's ramps read it as the full umbra or as two full ramps."""
    mesh = boxes_with_gap(0.01)
    az, el, radius = 180.0, 50.0, 1.0
    y = np.linspace(0.3, 1.0, 8)  # behind the boxes along the shadow (the sun is due south)
    points = np.c_[np.zeros_like(y), y, np.zeros_like(y)]
    truth = truth_alpha(mesh, points, az, el, radius)
    assert truth.min() < 0.8, "the gap should let through part of the sun"
    mdl = point_model(mesh, rule="wedge", profile="disk")
    got = 1.0 - np.asarray(mdl.at_points(ShadowParams(np.tan(np.radians(radius)), 0.0), Sun(az, el), Pose(),
                                         points))
    np.testing.assert_allclose(got, truth, atol=0.01)


def test_receivers_anywhere_match_ray_casting():
    """Points on a tilted plane under the slabs and on the pillar's own faces (light-space path:
    the depth complexity in front of each point by ray casting)."""
    az, el, radius = 200.0, 55.0, 1.5
    mesh = overlapping_slabs()
    rng = np.random.default_rng(3)
    xy = rng.uniform(-1.5, 1.5, (6000, 2))
    plane = np.c_[xy, 0.3 + 0.2 * xy[:, 0]]  # a tilted receiver between the ground and the slabs
    alpha = truth_alpha(mesh, plane, az, el, radius)
    keep = (alpha > 0.02) & (alpha < 0.98)
    points, alpha = plane[keep][:300], alpha[keep][:300]
    assert len(points) > 100
    mdl = point_model(mesh, rule="wedge", profile="disk")
    k = np.tan(np.radians(radius))
    got = 1.0 - np.asarray(mdl.at_points(ShadowParams(k, 0.0), Sun(az, el), Pose(), points, backend="light"))
    assert np.abs(got - alpha).max() < 0.02
    # Points on the pillar's shaded side, where the top casts nothing: attached shadow (normals).
    pillar = builtin_mesh("pillar")
    mdl = point_model(pillar, rule="wedge", profile="disk")
    faces = np.flatnonzero(np.abs(pillar.face_normals[:, 2]) < 0.5)
    centres = pillar.triangles_center[faces]
    normals = pillar.face_normals[faces]
    got = np.asarray(mdl.at_points(ShadowParams(0.01, 0.25), Sun(az, el), Pose(), centres, normals=normals))
    lit_side = normals @ Sun(az, el).light_np < 0
    np.testing.assert_allclose(got[~lit_side], 0.25)
    np.testing.assert_allclose(got[lit_side], 1.0)


@pytest.mark.parametrize("profile", ["linear", "disk"])
def test_a_lone_straight_edge_is_the_edge_rule(profile):
    """Across the long side of a wide wall, far from its ends, the wedge rule is the edge rule's
    profile with the same k, at points and as pixel means."""
    wall = trimesh.creation.box(extents=(8.0, 0.2, 1.0))
    wall.apply_translation([0.0, 0.0, 0.5])
    sun, pose, params = Sun(180.0, 40.0), Pose(), ShadowParams(0.02, 0.3)
    y = np.linspace(0.9, 1.5, 301)
    points = np.c_[np.full_like(y, 0.13), y, np.zeros_like(y)]
    edge = point_model(wall, rule="edge", profile=profile)
    wedge = point_model(wall, rule="wedge", profile=profile)
    np.testing.assert_allclose(wedge.at_points(params, sun, pose, points), edge.at_points(params, sun, pose, points),
                               atol=1e-9)
    # Pixel means: the two rules take u as linear over the pixel in two coordinates equal to
    # first order (the tangent of the angle about the edge, the distance in the sun's view), so
    # they differ by about k^2 of the ramp.
    grid = GroundGrid.around((0.13, 1.2), 0.5, 48)
    fp_edge = SoftShadowModel.from_mesh(wall, rule="edge", profile=profile, hidden_sky=False)
    fp_wedge = SoftShadowModel.from_mesh(wall, rule="wedge", profile=profile, hidden_sky=False)
    np.testing.assert_allclose(fp_wedge.ground_map(params, sun, pose, grid), fp_edge.ground_map(params, sun, pose, grid),
                               atol=1e-3)


def test_pixel_means_match_a_finer_map():
    """A ground map's pixel means (footprint on) against the 8 x 8 block means of a point-sampled
    map 8 times finer, on the slabs (overlaps, corners) and the pillar's base."""
    for mesh, centre, extent in ((overlapping_slabs(), (0.6, 1.0), 2.4), (builtin_mesh("pillar"), (0.0, 0.3), 0.6)):
        sun, pose, params = Sun(200.0, 55.0), Pose(), ShadowParams(0.02, 0.3)
        coarse = GroundGrid.around(centre, extent, 32)
        fine = GroundGrid.around(centre, extent, 256)
        mean = SoftShadowModel.from_mesh(mesh, rule="wedge", profile="disk", hidden_sky=False)
        got = np.asarray(mean.ground_map(params, sun, pose, coarse))
        ref = np.asarray(point_model(mesh, rule="wedge", profile="disk").ground_map(params, sun, pose, fine))
        ref = ref.reshape(32, 8, 32, 8).mean(axis=(1, 3))
        err = np.abs(got - ref)
        # The finer map steps by 1/8 pixel across a hard edge (the base): up to 0.7 / 16 off.
        assert err.max() < 0.05 and np.sqrt(np.mean(err ** 2)) < 0.004, (err.max(), np.sqrt(np.mean(err ** 2)))


def test_plans_agree_across_paths():
    """A grid plan, a point plan, the light-space path and concatenated plans give one map."""
    mdl = SoftShadowModel.from_mesh(overlapping_slabs(), rule="wedge", profile="disk", hidden_sky=False)
    sun, pose, params = Sun(200.0, 55.0), Pose(), ShadowParams(0.02, 0.3)
    grid = GroundGrid.around((0.6, 1.0), 2.4, 48)
    image = np.asarray(mdl.ground_map(params, sun, pose, grid)).ravel()
    points = grid.pixel_centres().reshape(-1, 3)
    axes = np.eye(2, 3) * grid.pixel_m
    np.testing.assert_allclose(mdl.at_points(params, sun, pose, points, pixel_axes=axes), image, atol=1e-12)
    np.testing.assert_allclose(mdl.at_points(params, sun, pose, points, pixel_axes=axes, backend="light"), image,
                               atol=1e-12)
    bare = mdl.with_options(footprint=False)
    values = np.asarray(bare.at_points(params, sun, pose, points))
    half = len(points) // 2
    plans = [bare.plan_points(sun, pose, points[:half], 0.02), bare.plan_points(sun, pose, points[half:], 0.02)]
    joined = concatenate_plans(plans, [half, len(points) - half])
    np.testing.assert_allclose(bare.at_points(params, sun, pose, points, plan=joined), values, atol=1e-12)


def test_float32_matches_float64():
    mdl = SoftShadowModel.from_mesh(overlapping_slabs(), rule="wedge", profile="disk")
    sun, pose = Sun(200.0, 55.0), Pose()
    grid = GroundGrid.around((0.6, 1.0), 2.4, 64)
    hi = np.asarray(mdl.ground_map(ShadowParams(0.02, 0.3), sun, pose, grid))
    with jax.enable_x64(False):
        lo = mdl.ground_map(ShadowParams(0.02, 0.3), sun, pose, grid)
        assert lo.dtype == np.float32
    assert np.abs(np.asarray(lo, np.float64) - hi).max() < 2e-4


# -- gradients: autodiff against central finite differences (float64, plan held fixed) ------------

def pillar_band_points(sun: Sun, pose: Pose, phase: float, height: float = 3.0, half_width: float = 0.3) -> np.ndarray:
    """Ground points (N, 3) on cross-sections of the pillar's shadow (half_width metres each side
    of its axis) and past its tip; ``phase`` in [0, 1) shifts them by a fraction of their spacing
    (generic points)."""
    light = np.asarray(sun.light_np)
    rot = np.asarray(pose.rotation)
    axis = np.array([[0.0, 0.0, 0.0], [0.0, 0.0, height]]) @ rot.T + np.asarray(pose.position, np.float64)
    ground = axis[:, :2] - (axis[:, 2] / light[2])[:, None] * light[:2]
    base, tip = ground
    along = (tip - base) / np.linalg.norm(tip - base)
    perp = np.array([-along[1], along[0]])
    offsets = (np.linspace(-1.0, 1.0, 121) + phase / 60.0) * half_width
    rows = [base + f * (tip - base) + offsets[:, None] * perp for f in (0.3, 0.6, 0.9)]
    rows += [tip + offsets[:, None] * along + o * perp for o in (-0.04, 0.017)]
    xy = np.concatenate(rows)
    return np.c_[xy, np.zeros(len(xy))]


gradient_scene = st.fixed_dictionaries({
    "range_k": st.floats(0.01, 0.04), "rho": st.floats(0.05, 0.95), "azimuth": st.floats(0.0, 360.0),
    "elevation": st.floats(20.0, 70.0), "x": st.floats(-1.0, 1.0), "y": st.floats(-1.0, 1.0),
    "z": st.floats(0.0, 0.3), "rot_x": st.floats(-10.0, 10.0), "rot_y": st.floats(-10.0, 10.0),
    "rot_z": st.floats(-180.0, 180.0), "phase": st.floats(0.05, 0.95)})

SKEWED_PIXEL = np.array([[0.011, 0.002, 0.0], [-0.003, 0.013, 0.0]])  # a skewed 1 cm pixel


@functools.cache
def wedge_pillar(profile: str) -> SoftShadowModel:
    return SoftShadowModel.from_mesh(builtin_mesh("pillar"), rule="wedge", profile=profile)


@pytest.mark.parametrize("profile,pixel", [("disk", False), ("linear", True)])
@settings(max_examples=4)  # each example: a plan, a forward Jacobian and 20 evaluations
@given(d=gradient_scene)
def test_point_gradients_match_finite_differences(profile, pixel, d):
    """Every parameter at generic penumbra points, sampled at the point and as pixel means (the
    default model's footprint); none is silently zero."""
    theta0 = np.array([d[name] for name in PARAM_NAMES], np.float64)
    _, sun, pose = unpack(jnp.asarray(theta0))
    points = pillar_band_points(sun, pose, d["phase"])
    jac = check_point_gradients(wedge_pillar(profile), theta0, points, 1.5 * d["range_k"],
                                pixel_axes=SKEWED_PIXEL if pixel else None)
    for i, name in enumerate(PARAM_NAMES):
        assert np.max(np.abs(jac[:, i])) > 1e-6, f"{name}: zero gradient across the whole penumbra"


def _theta(k, rho, sun: Sun, pose: Pose) -> np.ndarray:
    return np.r_[k, rho, float(sun.azimuth_deg), float(sun.elevation_deg), np.asarray(pose.position, float),
                 np.asarray(pose.rotation_deg, float)]


@pytest.mark.parametrize("pixel", [False, True])
def test_gradients_match_finite_differences_under_a_grazing_sun(pixel):
    """The sun 4 deg up: the pillar's shadow is 43 m long and its penumbra metres wide."""
    sun, pose = Sun(120.0, 4.0), Pose(rotation_deg=(0.0, 0.0, 10.0))
    points = pillar_band_points(sun, pose, 0.37, half_width=2.0)
    check_point_gradients(wedge_pillar("disk"), _theta(0.01, 0.3, sun, pose), points, 0.015, min_points=40,
                          pixel_axes=SKEWED_PIXEL * 5 if pixel else None)


@pytest.mark.parametrize("k", [1e-3, 1e-5])
def test_gradients_match_finite_differences_as_k_goes_to_zero(k):
    """Pixel means as k -> 0+: the penumbra (k d) is far narrower than the 1 cm pixel; the means
    still carry the hard shadow's area, differentiably. Points beside the pillar's side lines."""
    sun, pose = Sun(200.0, 35.0), Pose(rotation_deg=(0.0, 0.0, 15.0))
    points = pillar_band_points(sun, pose, 0.37)
    steps = STEPS.copy()
    steps[0] = 1e-5 * k
    check_point_gradients(wedge_pillar("disk"), _theta(k, 0.3, sun, pose), points, 1.5 * k, min_points=12,
                          pixel_axes=SKEWED_PIXEL, steps=steps, smooth_fraction=0.8)


def test_k_zero_is_the_limit_of_k_to_zero_with_finite_gradients():
    """At k = 0 the pixel means are the hard shadow's area in each pixel, the limit of k -> 0+
    (not the point-sampled hard shadow), and their gradients are finite."""
    mdl = wedge_pillar("disk").with_options(hidden_sky=False)
    sun, pose = Sun(200.0, 35.0), Pose(rotation_deg=(0.0, 0.0, 15.0))
    grid = GroundGrid.around((0.6, 1.6), 1.6, 48)
    at_zero, near_zero = k_zero_and_near_maps(mdl, sun, pose, grid)  # one compiled evaluation
    partial = (at_zero > 0.31) & (at_zero < 0.99)
    assert partial.sum() > 40, "the pixels on the outline should be partly shaded"
    assert np.abs(at_zero - near_zero).max() < 1e-4
    plan = fixed_shape_grid_plan(mdl, sun, pose, grid, 1e-6)
    grad = jax.grad(lambda t: jnp.sum(mdl.ground_map(*unpack(t), grid, plan=plan)))(
        jnp.asarray(_theta(0.0, 0.3, sun, pose)))
    assert np.all(np.isfinite(np.asarray(grad)))


def test_base_corner_pixel_is_continuous_with_matching_gradients():
    """The issue's case: pixels about the pillar's base corner under a low sun. Fresh plans at pose
    x = -h and +h differ by O(h) (no jump), their central differences agree with autodiff."""
    mdl = wedge_pillar("disk")
    sun, params = Sun(200.0, 5.0), ShadowParams(0.0046, 0.3)
    axes = np.eye(2, 3) * 0.01
    offsets = (np.arange(-2, 3) + 0.3) * 0.01  # the corner (0.1, -0.1) inside the middle pixel
    points = np.array([[0.1 + a, -0.1 + b, 0.0] for a in offsets for b in offsets])

    def fresh(x):
        return np.asarray(mdl.at_points(params, sun, Pose(position=(x, 0.0, 0.0)), points, pixel_axes=axes,
                                        range_k_max=0.007))

    plan = mdl.plan_points(sun, Pose(), points, 0.007, pixel_axes=axes)
    autodiff = np.asarray(jax.jacfwd(lambda x: mdl.at_points(params, sun, Pose(position=jnp.stack([x, 0.0, 0.0])),
                                                             points, pixel_axes=axes, plan=plan))(jnp.asarray(0.0)))
    assert np.abs(autodiff).max() > 10.0, "the corner's pixels should move with the pillar"
    for h in (1e-5, 1e-6):
        plus, minus = fresh(h), fresh(-h)
        assert np.abs(plus - minus).max() < 200 * h
        np.testing.assert_allclose((plus - minus) / (2 * h), autodiff, atol=0.5)


def test_float32_gradients_match_float64():
    """The float32 path's gradients (k, rho, sun, pose) against float64's, pixel means on."""
    mdl = wedge_pillar("disk").with_options(hidden_sky=False)
    sun, pose = Sun(150.0, 45.0), Pose(rotation_deg=(0.0, 0.0, 25.0))
    grid = GroundGrid.around((0.6, 1.6), 2.4, 48)
    plan = fixed_shape_grid_plan(mdl, sun, pose, grid, 0.03)
    theta = _theta(0.02, 0.3, sun, pose)
    weights = np.random.default_rng(5).standard_normal((48, 48))

    def grad_in(dtype):
        loss = lambda t: jnp.sum(jnp.asarray(weights, dtype) * mdl.ground_map(*unpack(t), grid, plan=plan))
        return np.asarray(jax.grad(loss)(jnp.asarray(theta, dtype)), np.float64)

    hi = grad_in(jnp.float64)
    with jax.enable_x64(False):
        lo = grad_in(jnp.float32)
    assert np.all(np.isfinite(lo))
    np.testing.assert_allclose(lo, hi, rtol=2e-2, atol=2e-3 * np.abs(hi).max())
