"""The light-space back end (the sun's shadow map): receivers of any shape.

- On the plane z = 0 it agrees with the ground back end (``ground_map``): the
  50 % contour within 0.5 px, alpha within 0.01 RMS.
- k = 0 equals the hard shadow by ray casting (trimesh) on steps and a wall.
- The depth test's bias: no acne (a lit surface of the object does not
  shadow itself, also at grazing light), no peter-panning beyond the stated
  bias (a plate leaning on the ground).
- Attached shadow: n . L >= 0 gives alpha = 1.
- Gradients in k, rho, the sun and the pose on steps, a slope and a wall
  (hypothesis, float64, central differences), finite at hard cases; float32.
- The shadow-map rasteriser against a brute-force one.
"""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
import numpy as np
import pytest
import trimesh
from hypothesis import assume, given
from scipy.spatial import cKDTree
from skimage.measure import find_contours

from softshadow import GroundGrid, Pose, ShadowParams, SoftShadowModel, Sun
from softshadow.internal import object_mask, project_to_ground
from softshadow.meshes import builtin_mesh
from softshadow.shadowmap import BIAS_PX, LightFrame, depth_bias, faces_away, rasterise_depth
from test_render_gradients import check_point_gradients, pillar_shadow_samples, scene, theta_of, unpack


# These tests check the model's geometry at points: pixel centres sampled, no hidden sky
# (the pixel footprint and the sky have their own tests in test_render_floor.py).
point_model = functools.partial(SoftShadowModel.from_mesh, footprint=False, hidden_sky=False)


@functools.cache
def builtin_model(name: str, rule: str = "edge", profile: str = "linear") -> SoftShadowModel:
    return point_model(builtin_mesh(name), rule=rule, profile=profile)


def posed_trimesh(mesh: trimesh.Trimesh, pose: Pose) -> trimesh.Trimesh:
    out = mesh.copy()
    transform = np.eye(4)
    transform[:3, :3] = np.asarray(pose.rotation) * float(pose.scale)
    transform[:3, 3] = np.asarray(pose.position)
    out.apply_transform(transform)
    return out


def to_sun(sun: Sun) -> np.ndarray:
    return -np.asarray(sun.light_np)


def steps_mesh(direction_xy, start: float, rise: float = 0.15, run: float = 0.4, n: int = 3,
               origin=(0.0, 0.0)) -> trimesh.Trimesh:
    """The ground z = 0 and ``n`` steps up along ``direction_xy``, the first riser ``start`` m
    from ``origin``."""
    d = np.asarray(direction_xy, float)
    d = d / np.linalg.norm(d)
    yaw = np.arctan2(d[1], d[0])
    parts = [trimesh.creation.box(extents=(20.0, 20.0, 0.02),
                                  transform=trimesh.transformations.translation_matrix((0, 0, -0.01)))]
    for i in range(n):
        length = 10.0
        box = trimesh.creation.box(extents=(length, 12.0, rise * (i + 1)))
        centre = np.array([start + i * run + length / 2, 0.0, rise * (i + 1) / 2])
        rot = trimesh.transformations.rotation_matrix(yaw, (0, 0, 1))
        box.apply_translation(centre)
        box.apply_transform(rot)
        box.apply_translation((origin[0], origin[1], 0.0))
        parts.append(box)
    return trimesh.util.concatenate(parts)


def wall_mesh(direction_xy, distance: float, origin=(0.0, 0.0)) -> trimesh.Trimesh:
    """The ground and a 3 m wall across ``direction_xy``, ``distance`` m from ``origin``."""
    d = np.asarray(direction_xy, float)
    d = d / np.linalg.norm(d)
    yaw = np.arctan2(d[1], d[0])
    ground = trimesh.creation.box(extents=(20.0, 20.0, 0.02),
                                  transform=trimesh.transformations.translation_matrix((0, 0, -0.01)))
    wall = trimesh.creation.box(extents=(0.3, 12.0, 3.0))
    wall.apply_translation((distance + 0.15, 0.0, 1.5))
    wall.apply_transform(trimesh.transformations.rotation_matrix(yaw, (0, 0, 1)))
    wall.apply_translation((origin[0], origin[1], 0.0))
    return trimesh.util.concatenate([ground, wall])


def slope_mesh(direction_xy, grade: float = 0.25, origin=(0.0, 0.0)) -> trimesh.Trimesh:
    """A plane rising along ``direction_xy`` at ``grade``, through ``origin`` at z = 0."""
    d = np.asarray(direction_xy, float)
    d = d / np.linalg.norm(d)
    o = np.array([origin[0], origin[1], 0.0])
    e = np.array([d[0], d[1], grade])
    f = np.array([-d[1], d[0], 0.0])
    corners = [o + a * 10 * e + b * 10 * f for a, b in ((-1, -1), (1, -1), (1, 1), (-1, 1))]
    return trimesh.Trimesh(corners, [[0, 1, 2], [0, 2, 3]], process=False)


def seen_from_sun(receiver: trimesh.Trimesh, ground_points: np.ndarray, light: np.ndarray):
    """Receiver points (M, 3) and normals (M, 3) first hit from the sun along the light lines
    through ground points (N, 2 or 3): the receiver surface at the same light-space position."""
    g = np.c_[ground_points[:, :2], np.zeros(len(ground_points))]
    origins = g - 30.0 * light
    loc, ray, tri = receiver.ray.intersects_location(origins, np.tile(light, (len(g), 1)),
                                                     multiple_hits=False)
    order = np.argsort(ray)
    normals = receiver.face_normals[tri[order]]
    normals = np.where((normals @ light)[:, None] > 0, -normals, normals)  # the side facing the sun
    return loc[order], normals


def shadow_direction(sun: Sun) -> np.ndarray:
    light = np.asarray(sun.light_np)
    return light[:2] / np.linalg.norm(light[:2])


def raycast_hard(occluder: trimesh.Trimesh, points: np.ndarray, normals: np.ndarray, sun: Sun) -> np.ndarray:
    """Ground truth: the ray from each point (nudged off its surface) towards the sun hits the occluder."""
    s = to_sun(sun)
    origins = points + 1e-6 * normals
    return occluder.ray.intersects_any(origins, np.tile(s, (len(points), 1)))


# -- the plane: agreement with the ground back end ----------------------------------------------

def contour_distance_px(a: np.ndarray, b: np.ndarray, level: float = 0.5) -> float:
    """Largest distance (pixels) from a point of one image's level contour to the other's."""
    ca = np.concatenate(find_contours(a, level))
    cb = np.concatenate(find_contours(b, level))
    return float(max(cKDTree(cb).query(ca)[0].max(), cKDTree(ca).query(cb)[0].max()))


@pytest.mark.parametrize("name,sun,pose", [
    ("pillar", Sun(200.0, 40.0), Pose()),
    ("ball", Sun(120.0, 35.0), Pose((0.2, -0.1, 0.0), (5.0, 0.0, 30.0))),
    ("box", Sun(250.0, 30.0), Pose((0.0, 0.0, 0.0), (0.0, 0.0, 20.0))),
])
def test_plane_agrees_with_the_ground_back_end(name, sun, pose):
    """(The dragon's many short outline edges make any two rasters choose differently near its
    folds: docs/shadow_map.md gives its figures, and the ground back end's own two rasters'.)"""
    if name == "box":
        box = trimesh.creation.box(extents=(0.6, 0.4, 1.0))
        box.apply_translation((0.0, 0.0, 0.5))
        mdl = point_model(box)
    else:
        mdl = builtin_model(name)
    params = ShadowParams(0.02, 0.3)
    world = np.asarray(mdl.occluder.vertices) @ np.asarray(pose.rotation).T + np.asarray(pose.position)
    pts = np.vstack([project_to_ground(world, sun.light_np), world[:, :2]])
    grid = GroundGrid.around((pts.min(0) + pts.max(0)) / 2, float((pts.max(0) - pts.min(0)).max()) * 1.1, 160)
    ground = np.asarray(mdl.ground_map(params, sun, pose, grid))
    points = grid.pixel_centres().reshape(-1, 3)
    light = np.asarray(mdl.at_points(params, sun, pose, points, backend="light",
                                     pixel_m=grid.pixel_m)).reshape(grid.height, grid.width)
    # The ground under the object is hidden by it (and on its bottom face): left out.
    hidden = object_mask(mdl.occluder, pose, grid)
    alpha_g, alpha_l = (1 - ground) / 0.7, (1 - light) / 0.7
    rms = float(np.sqrt(np.mean((alpha_g - alpha_l)[~hidden] ** 2)))
    assert rms <= 0.01, f"alpha differs by {rms:.4f} RMS from the ground back end"
    alpha_g[hidden] = alpha_l[hidden] = 1.0
    dist = contour_distance_px(alpha_g, alpha_l)
    assert dist <= 0.5, f"the 50 % contours lie {dist:.3f} px apart"


def test_auto_backend_takes_the_ground_for_plane_points():
    mdl = builtin_model("pillar")
    sun, pose = Sun(150.0, 40.0), Pose()
    pts = pillar_shadow_samples(sun, pose)
    auto = mdl.plan_points(sun, pose, pts, 0.02)
    ground = mdl.plan_points(sun, pose, pts, 0.02, backend="ground")
    for a, b in zip(jax.tree_util.tree_leaves(auto), jax.tree_util.tree_leaves(ground)):
        np.testing.assert_array_equal(a, b)
    with pytest.raises(ValueError, match="back end"):
        mdl.plan_points(sun, pose, pts, 0.02, backend="sideways")


# -- hard shadow against ray casting on receivers that are not planar --------------------------

RECEIVERS = ("steps", "wall", "slope")


def receiver_for(kind: str, sun: Sun, pose: Pose, start: float = 0.5) -> trimesh.Trimesh:
    d = shadow_direction(sun)
    o = np.asarray(pose.position)[:2]
    if kind == "steps":
        return steps_mesh(d, start, origin=o)
    if kind == "wall":
        return wall_mesh(d, start + 0.3, origin=o)
    return slope_mesh(d, 0.25, origin=o - 0.3 * d)


@pytest.mark.parametrize("name,kind", [("pillar", "steps"), ("pillar", "wall"), ("ball", "slope"),
                                       ("dragon", "steps"), ("dragon", "wall")])
def test_hard_shadow_matches_ray_casting(name, kind):
    mdl = builtin_model(name)
    sun, pose = Sun(200.0, 40.0), Pose((0.0, 0.0, 0.3 if name == "ball" else 0.0), (0.0, 0.0, 15.0))
    receiver = receiver_for(kind, sun, pose, start=0.4)
    occ_mesh = posed_trimesh(builtin_mesh(name), pose)
    # Light-space samples over the shadow's region, lifted onto the receiver.
    world = np.asarray(occ_mesh.vertices)
    g = np.vstack([project_to_ground(world, sun.light_np), world[:, :2]])
    lo, hi = g.min(0) - 0.2, g.max(0) + 0.2
    xy = np.stack(np.meshgrid(np.linspace(lo[0], hi[0], 110), np.linspace(lo[1], hi[1], 110)), -1).reshape(-1, 2)
    points, normals = seen_from_sun(receiver, xy, np.asarray(sun.light_np))
    # Leave out points inside the object (the ground under its base).
    points, normals = points[~occ_mesh.contains(points)], normals[~occ_mesh.contains(points)]
    truth = raycast_hard(occ_mesh, points, normals, sun)
    pixel_m = 0.01
    plan = mdl.plan_points(sun, pose, points, 0.0, normals, pixel_m=pixel_m)
    hard = plan.hard[:len(points)] > 0.5
    shading = np.asarray(mdl.at_points(ShadowParams(0.0, 0.0), sun, pose, points, normals, plan=plan))
    np.testing.assert_array_equal(shading < 0.5, hard)  # k = 0 is the plan's hard shadow
    wrong = np.flatnonzero(hard != truth)
    assert truth.sum() > 200 and (~truth).sum() > 200
    # A mismatch may only sit on the outline: within a raster pixel (seen from the sun) of a
    # point of the other class.
    frame = LightFrame.of_light(sun.light_np)
    uv, _ = frame.project(points)
    tree_in, tree_out = cKDTree(uv[truth]), cKDTree(uv[~truth])
    d = np.where(truth[wrong], tree_out.query(uv[wrong])[0], tree_in.query(uv[wrong])[0])
    spacing = float(np.median(cKDTree(uv).query(uv, k=2)[0][:, 1]))
    assert len(wrong) <= 0.01 * len(points), f"{len(wrong)} of {len(points)} points differ from ray casting"
    assert np.all(d <= 1.5 * spacing + 1.5 * pixel_m), f"mismatches off the outline: {np.sort(d)[-5:]}"


# -- the depth test's bias: acne and peter-panning ----------------------------------------------

def plate(tilt_deg: float, thickness: float = 0.02) -> trimesh.Trimesh:
    """A 1 m x 1 m plate, centred 1 m up, tilted about x by ``tilt_deg``."""
    box = trimesh.creation.box(extents=(1.0, 1.0, thickness))
    box.apply_transform(trimesh.transformations.rotation_matrix(np.deg2rad(tilt_deg), (1, 0, 0)))
    box.apply_translation((0.0, 0.0, 1.0))
    return box


def surface_samples(mesh: trimesh.Trimesh, count: int, seed: int = 0):
    pts, face = trimesh.sample.sample_surface_even(mesh, count, seed=seed)
    return np.asarray(pts), mesh.face_normals[face]


@pytest.mark.parametrize("grazing_deg", [30.0, 60.0, 80.0, 85.0])
def test_no_acne_on_a_lit_plate(grazing_deg):
    """The lit face of a plate, at an angle of incidence from 30 to 85 deg: nothing is shadowed."""
    sun = Sun(180.0, 50.0)  # light towards +y, down
    # Tilt the plate about x so that its top face's normal makes ``grazing_deg`` with the sun.
    tilt = 90.0 - 50.0 - grazing_deg  # normal (0, -sin t, cos t) against s = (0, -cos 50, sin 50)
    mesh = plate(tilt)
    mdl = point_model(mesh)
    pts, nrm = surface_samples(mesh, 3000)
    top = nrm @ np.array([0.0, -np.sin(np.deg2rad(tilt)), np.cos(np.deg2rad(tilt))]) > 0.999
    incidence = np.degrees(np.arccos(np.clip(nrm[top] @ to_sun(sun), -1, 1)))
    np.testing.assert_allclose(incidence, grazing_deg, atol=1e-6)
    shading = np.asarray(mdl.at_points(ShadowParams(0.01, 0.2), sun, Pose(), pts, nrm))
    assert np.all(shading[top] == 1.0), f"{np.count_nonzero(shading[top] < 1)} lit points darkened (acne)"
    away = faces_away(nrm, sun.light_np)
    assert away.sum() > 500
    np.testing.assert_allclose(shading[away], 0.2)  # the far faces: attached shadow


@pytest.mark.parametrize("name", ["ball", "dragon"])
def test_object_receives_its_own_shadow_without_acne(name):
    """Points on the object itself: the sun side is lit unless another part of the object is in
    the way (ray casting), the far side is in attached shadow."""
    mesh = builtin_mesh(name)
    mdl = builtin_model(name)
    sun = Sun(200.0, 40.0)
    pts, nrm = surface_samples(mesh, 4000, seed=1)
    plan = mdl.plan_points(sun, Pose(), pts, 0.0, nrm)
    hard = plan.hard[:len(pts)] > 0.5
    away = faces_away(nrm, sun.light_np)
    assert np.all(hard[away])
    front = ~away
    truth = raycast_hard(mesh, pts[front], nrm[front], sun)
    acne = np.count_nonzero(hard[front] & ~truth)
    missed = np.count_nonzero(~hard[front] & truth)
    # A mismatch is a point within a raster pixel of where the object's own shadow begins.
    assert acne <= 0.005 * front.sum(), f"{acne} of {front.sum()} lit points shadowed (acne)"
    assert missed <= 0.01 * front.sum(), f"{missed} of {front.sum()} shadowed points lit"
    if name == "ball":
        assert acne == 0 and missed == 0  # convex: no cast shadow on itself


def test_contact_shadow_is_not_detached_beyond_the_bias():
    """A plate leaning on the ground: on the ground behind its lower edge, every point whose gap
    to the plate along the light exceeds the stated bias is in shadow (no peter-panning)."""
    sun = Sun(180.0, 40.0)
    box = trimesh.creation.box(extents=(1.0, 0.02, 1.0))
    box.apply_transform(trimesh.transformations.rotation_matrix(np.deg2rad(-30.0), (1, 0, 0)))
    box.apply_translation((0.0, 0.0, -box.bounds[0, 2]))  # resting on z = 0
    mdl = point_model(box)
    y0 = box.vertices[np.argmin(box.vertices[:, 2]), 1]
    y = y0 + np.linspace(-0.02, 0.4, 800)
    pts = np.c_[np.zeros_like(y), y, np.zeros_like(y)]
    up = np.tile([0.0, 0.0, 1.0], (len(y), 1))
    pixel_m = 0.004
    plan = mdl.plan_points(sun, Pose(), pts, 0.0, up, pixel_m=pixel_m, backend="light")
    hard = plan.hard[:len(y)] > 0.5
    loc, ray, _ = box.ray.intersects_location(pts, np.tile(to_sun(sun), (len(y), 1)), multiple_hits=False)
    gap = np.full(len(y), np.inf)
    gap[ray] = np.linalg.norm(loc - pts[ray], axis=1)
    scale = float(np.abs(np.r_[box.vertices.ravel(), pts.ravel()]).max()) * 2
    bias = float(depth_bias(pixel_m, 0.0, 0.0, scale))
    assert bias <= BIAS_PX * pixel_m * 1.01
    under = (gap > bias) & np.isfinite(gap)
    assert under.sum() > 100
    assert np.all(hard[under]), f"detached: {np.count_nonzero(~hard[under])} points more than the bias behind"
    assert not np.any(hard[~np.isfinite(gap)])


# -- attached shadow ------------------------------------------------------------------------------

def test_attached_shadow_from_normals():
    mdl = builtin_model("pillar")
    sun = Sun(90.0, 30.0)  # the sun in the east
    pts = np.array([[5.0, 5.0, 0.0], [5.0, 6.0, 0.0], [6.0, 5.0, 0.3], [7.0, 5.0, 0.3]])
    normals = np.array([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [1.0, 0.0, 0.0],
                        -np.asarray(sun.light_np) * 0 + [0.0, np.sqrt(0.5), -np.sqrt(0.5)]])
    shading = np.asarray(mdl.at_points(ShadowParams(0.01, 0.25), sun, Pose(), pts, normals))
    away = faces_away(normals, sun.light_np)
    np.testing.assert_array_equal(away, [False, True, False, True])
    np.testing.assert_allclose(shading, np.where(away, 0.25, 1.0))
    with pytest.raises(ValueError, match="normals"):
        mdl.plan_points(sun, Pose(), pts, 0.01, normals[:2])


# -- gradients on receivers that are not planar ---------------------------------------------------

def lifted_samples(kind: str, sun: Sun, pose: Pose, phase: float) -> np.ndarray:
    """Sample lines across the pillar's shadow (as on the ground), lifted along the light onto
    the receiver: the same light-space positions, so they still cross the penumbra."""
    ground = pillar_shadow_samples(sun, pose, phase=phase)
    points, _ = seen_from_sun(receiver_for(kind, sun, pose), ground, np.asarray(sun.light_np))
    return points


@pytest.mark.parametrize("kind", RECEIVERS)
@given(d=scene)
def test_gradients_on_receivers_that_are_not_planar(kind, d):
    theta0 = theta_of(d)
    mdl = builtin_model("pillar", "edge", "linear")
    _, sun, pose = unpack(jnp.asarray(theta0))
    points = lifted_samples(kind, sun, pose, d["phase"])
    assume(np.ptp(points[:, 2]) > 0.05)  # the samples cross the receiver's relief
    plan = mdl.plan_points(sun, pose, points, 1.5 * d["range_k"])
    assert plan.active.any()
    check_point_gradients(mdl, theta0, points, 1.5 * d["range_k"])


def test_paper_rule_and_disk_profile_gradients_on_steps():
    theta0 = np.array([0.03, 0.3, 150.0, 45.0, 0.1, -0.2, 0.1, 3.0, -4.0, 25.0])
    mdl = builtin_model("pillar", "paper", "disk")
    _, sun, pose = unpack(jnp.asarray(theta0))
    check_point_gradients(mdl, theta0, lifted_samples("steps", sun, pose, 0.41), 0.045)


# -- hard cases and float32 --------------------------------------------------------------------

@pytest.mark.parametrize("sun", [Sun(200.0, 40.0), Sun(10.0, 89.9)])
def test_finite_at_hard_cases(sun):
    """Values and gradients finite at k = 0, 1e-12 and 0.02, for points on the occluder's own
    vertices and edges, receiver points on steps, and normals exactly edge-on to the light
    (attached shadow); at an ordinary sun and at the zenith."""
    mdl = builtin_model("pillar")
    pose = Pose()
    v = np.asarray(mdl.occluder.vertices)
    e = mdl.occluder.edges
    rng = np.random.default_rng(3)
    if sun.elevation_deg > 89:
        steps = np.c_[rng.uniform(-0.3, 0.3, (1500, 2)), rng.uniform(0.0, 0.2, 1500)]
    else:
        steps = lifted_samples("steps", sun, pose, 0.3)
    pts = np.vstack([v, 0.5 * (v[e[:, 0]] + v[e[:, 1]]), steps])
    light = np.asarray(sun.light_np)
    side = np.cross(light, [0.0, 0.0, 1.0])
    normals = np.tile([0.0, 0.0, 1.0], (len(pts), 1))
    edge_on = np.arange(len(pts)) % 5 == 0
    normals[edge_on] = side / np.linalg.norm(side)
    assert np.all(faces_away(normals[edge_on], light))
    plan = mdl.plan_points(sun, pose, pts, 0.02, normals, backend="light")
    assert np.all(plan.hard[:len(pts)][edge_on] == 1.0)

    def loss(params, s, q):
        return jnp.sum(mdl.at_points(params, s, q, pts, normals, plan=plan))

    for k in (0.0, 1e-12, 0.02):  # one plan (its band holds up to k = 0.02): one compile
        value, grads = jax.value_and_grad(loss, argnums=(0, 1, 2))(ShadowParams(k, 0.3), sun, pose)
        assert np.isfinite(float(value))
        assert all(np.all(np.isfinite(np.asarray(g))) for g in jax.tree_util.tree_leaves(grads))


def test_float32_depth_test_and_alpha_agree_with_float64():
    mdl = builtin_model("dragon")
    sun, pose = Sun(200.0, 40.0), Pose()
    receiver = receiver_for("steps", sun, pose, start=0.4)
    g = np.stack(np.meshgrid(np.linspace(-1.0, 1.2, 90), np.linspace(-1.0, 2.2, 90)), -1).reshape(-1, 2)
    pts, nrm = seen_from_sun(receiver, g, np.asarray(sun.light_np))
    obj, onrm = surface_samples(builtin_mesh("dragon"), 2000, seed=2)
    pts, nrm = np.vstack([pts, obj]), np.vstack([nrm, onrm])
    p64 = mdl.plan_points(sun, pose, pts, 0.02, nrm)
    p32 = mdl.plan_points(sun, pose, pts, 0.02, nrm, dtype=np.float32)
    n = len(pts)
    flips = np.count_nonzero(p64.hard[:n] != p32.hard[:n])
    assert flips <= 2, f"{flips} hard-shadow decisions change in float32"
    params = ShadowParams(0.02, 0.3)
    a64 = np.asarray(mdl.at_points(params, sun, pose, pts, nrm, plan=p64))
    with jax.enable_x64(False):
        a32 = np.asarray(mdl.at_points(ShadowParams(np.float32(0.02), np.float32(0.3)), sun, pose,
                                       pts.astype(np.float32), nrm, plan=p32))
    assert a32.dtype == np.float32
    assert np.sqrt(np.mean((a64 - a32) ** 2)) < 1e-3


# -- the rasteriser -----------------------------------------------------------------------------

def test_rasterise_depth_matches_brute_force():
    rng = np.random.default_rng(1)
    xy = rng.uniform(-3, 30, (120, 2))
    depth = rng.uniform(0, 1, 120)
    faces = rng.integers(0, 120, (80, 3))
    z, fid = rasterise_depth(xy, depth, faces, (28, 25))
    rows, cols = np.mgrid[0:28, 0:25]
    p = np.stack([cols.ravel(), rows.ravel()], 1).astype(float)
    ref = np.full(p.shape[0], np.inf)
    ref_id = np.full(p.shape[0], -1)
    for i, f in enumerate(faces):
        a, b, c = xy[f]
        m = np.array([b - a, c - a]).T
        if abs(np.linalg.det(m)) < 1e-12:
            continue
        bary = np.linalg.solve(m, (p - a).T).T
        inside = (bary >= -1e-9).all(1) & (bary.sum(1) <= 1 + 1e-9)
        zz = depth[f[0]] + bary @ (depth[f[1:]] - depth[f[0]])
        better = inside & (zz < ref)
        ref[better], ref_id[better] = zz[better], i
    np.testing.assert_array_equal(fid.ravel(), ref_id)
    np.testing.assert_allclose(z.ravel()[ref_id >= 0], ref[ref_id >= 0], atol=1e-12)
    assert np.all(np.isinf(z.ravel()[ref_id < 0]))
