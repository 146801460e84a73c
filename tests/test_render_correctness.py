"""The soft shadow renderer against independent computations.

- k = 0: the ground map equals the hard shadow found by casting rays from each
  pixel centre towards the sun against the posed mesh (trimesh), up to pixels
  within a pixel of the boundary; k > 0: the alpha = 0.5 contour is that same
  boundary (the `edge` rule's penumbra is centred on the hard silhouette) and
  the umbra / lit regions beyond the widest penumbra are exactly 1 / 0.
- Box and cylinder: analytic footprints (the projected vertices' hull; two
  circles joined by tangents).
- alpha in [0, 1]; rho = 1 is all lit; translation shifts the map; the ramp
  width across an edge is the model's 2 k d times the ground stretch (computed
  here by projecting along L +- k n); the disk profile has the linear one's end
  points; the paper rule's width is (N . n) times the edge rule's.
- Consistency: ground map vs values at points vs a camera looking straight
  down; a box lit exactly side-on vs the sun turned by 1e-6 degrees.
"""

from __future__ import annotations

import functools

import cv2
import numpy as np
import pytest
import trimesh
from hypothesis import given
from hypothesis import strategies as st
from matplotlib.path import Path
from scipy.spatial import ConvexHull

from gradcheck import fixed_shape_grid_plan
from softshadow import GroundGrid, Pose, ShadowParams, SoftShadowModel, Sun, look_at_camera
from softshadow.meshes import builtin_mesh


# These tests check the model's geometry at points: pixel centres sampled, no hidden sky
# (the pixel footprint and the sky have their own tests in test_render_floor.py).
point_model = functools.partial(SoftShadowModel.from_mesh, footprint=False, hidden_sky=False)


@functools.cache
def builtin_model(name: str, rule: str = "edge", profile: str = "linear") -> SoftShadowModel:
    return point_model(builtin_mesh(name), rule=rule, profile=profile)


def standing_box(extents) -> trimesh.Trimesh:
    box = trimesh.creation.box(extents=extents)
    box.apply_translation([0.0, 0.0, extents[2] / 2])
    return box


def standing_cylinder(radius=0.25, height=1.2, sections=64) -> trimesh.Trimesh:
    cyl = trimesh.creation.cylinder(radius=radius, height=height, sections=sections)
    cyl.apply_translation([0.0, 0.0, height / 2])
    return cyl


def posed_mesh(mesh: trimesh.Trimesh, pose: Pose) -> trimesh.Trimesh:
    """The mesh moved to world coordinates: x_world = R (s x) + p (independent of the package's NumPy twin)."""
    transform = np.eye(4)
    transform[:3, :3] = np.asarray(pose.rotation) * float(pose.scale)
    transform[:3, 3] = np.asarray(pose.position)
    out = mesh.copy()
    out.apply_transform(transform)
    return out


def sun_vector(sun: Sun) -> np.ndarray:
    a, e = np.radians(float(sun.azimuth_deg)), np.radians(float(sun.elevation_deg))
    return np.array([np.sin(a) * np.cos(e), np.cos(a) * np.cos(e), np.sin(e)])


def raycast_shadow(mesh: trimesh.Trimesh, pose: Pose, sun: Sun, grid: GroundGrid) -> np.ndarray:
    """Hard shadow (H, W) bool: does the ray from the pixel centre towards the sun hit the mesh."""
    world = posed_mesh(mesh, pose)
    s = sun_vector(sun)
    origins = grid.pixel_centres().reshape(-1, 3) + 1e-7 * s
    hit = world.ray.intersects_any(origins, np.tile(s, (len(origins), 1)))
    return hit.reshape(grid.height, grid.width)


def distance_to_other_class(mask: np.ndarray) -> np.ndarray:
    """Per pixel, the distance in pixels to the nearest pixel of the other class (exact Euclidean)."""
    m = mask.astype(np.uint8)
    d_in = cv2.distanceTransform(m, cv2.DIST_L2, cv2.DIST_MASK_PRECISE)
    d_out = cv2.distanceTransform(1 - m, cv2.DIST_L2, cv2.DIST_MASK_PRECISE)
    return np.where(mask, d_in, d_out)


def alpha_map(mdl, k, sun, pose, grid, rho=0.3):
    shading = np.asarray(mdl.ground_map(ShadowParams(k, rho), sun, pose, grid, range_k_max=k))
    return (1.0 - shading) / (1.0 - rho)


def widest_half_penumbra(mesh_z_max: float, k: float, sun: Sun) -> float:
    """Upper bound of the ground half-width of any edge's penumbra: k d / sin E, d <= z / sin E."""
    sin_e = np.sin(np.radians(float(sun.elevation_deg)))
    return k * mesh_z_max / sin_e ** 2


# -- against ray casting ------------------------------------------------------------------------

RAY_SCENES = [
    ("pillar", Sun(135.0, 40.0), Pose(), GroundGrid.around((-1.6, 1.6), 5.0, 128)),
    ("pillar", Sun(250.0, 55.0), Pose(position=(0.7, -0.4, 0.0), rotation_deg=(4.0, -3.0, 33.0)),
     GroundGrid.around((1.9, 0.1), 4.0, 128)),
    ("ball", Sun(135.0, 40.0), Pose(), GroundGrid.around((-1.2, 1.2), 3.5, 128)),
    ("ball", Sun(20.0, 60.0), Pose(position=(-0.3, 0.5, 0.2), rotation_deg=(0.0, 10.0, 70.0)),
     GroundGrid.around((-0.7, -0.5), 3.0, 128)),
    ("dragon", Sun(135.0, 40.0), Pose(), GroundGrid.around((-0.6, 0.6), 3.0, 128)),
    ("dragon", Sun(300.0, 50.0), Pose(position=(0.4, 0.2, 0.0), rotation_deg=(0.0, 0.0, -40.0)),
     GroundGrid.around((1.1, -0.1), 3.0, 128)),
]


@pytest.mark.parametrize("name,sun,pose,grid", RAY_SCENES,
                         ids=[f"{s[0]}-{i}" for i, s in enumerate(RAY_SCENES)])
def test_k_zero_equals_ray_cast_hard_shadow(name, sun, pose, grid):
    truth = raycast_shadow(builtin_mesh(name), pose, sun, grid)
    alpha = alpha_map(builtin_model(name), 0.0, sun, pose, grid)
    assert set(np.unique(np.round(alpha, 12))) <= {0.0, 1.0}, "k = 0 must be a hard shadow"
    model = alpha > 0.5
    assert truth.sum() > 300
    wrong = model != truth
    far = distance_to_other_class(truth) > 1.5
    assert not np.any(wrong & far), (
        f"{int(np.sum(wrong & far))} pixels disagree with ray casting more than a pixel from the "
        f"boundary (of {int(truth.sum())} in shadow)")
    assert wrong.sum() <= 0.02 * truth.sum()


@pytest.mark.parametrize("name,sun,pose,grid", [
    pytest.param(*s, marks=pytest.mark.xfail(
        reason="known limitation of the edge-based model: the dragon's gaps narrower than a penumbra "
               "get a full ramp on both sides, so a few umbra pixels more than a pixel from the hard "
               "boundary fall below alpha = 0.5 (6 and 2 pixels, alpha 0.26 and 0.32)", strict=True))
    if s[0] == "dragon" else s for s in RAY_SCENES],
                         ids=[f"{s[0]}-{i}" for i, s in enumerate(RAY_SCENES)])
def test_soft_shadow_is_centred_on_the_ray_cast_boundary(name, sun, pose, grid):
    """Edge rule, k > 0: alpha >= 0.5 exactly on the hard shadow (up to boundary pixels); beyond the
    widest penumbra half-width the map is pure umbra inside and pure lit outside."""
    k = 0.02
    truth = raycast_shadow(builtin_mesh(name), pose, sun, grid)
    alpha = alpha_map(builtin_model(name), k, sun, pose, grid)
    assert alpha.min() >= -1e-12 and alpha.max() <= 1 + 1e-12
    dist_px = distance_to_other_class(truth)
    wrong = (alpha >= 0.5) != truth
    far = dist_px > 1.5
    assert not np.any(wrong & far), (
        f"{int(np.sum(wrong & far))} pixels on the wrong side of alpha = 0.5 more than a pixel from "
        f"the hard boundary; worst alpha inside {alpha[truth & far].min():.3f}, "
        f"outside {alpha[~truth & far].max():.3f}")
    z_max = posed_mesh(builtin_mesh(name), pose).bounds[1, 2]
    beyond = dist_px * grid.pixel_m > widest_half_penumbra(z_max, k, sun) + 1.5 * grid.pixel_m
    np.testing.assert_allclose(alpha[truth & beyond], 1.0, atol=1e-9)
    np.testing.assert_allclose(alpha[~truth & beyond], 0.0, atol=1e-9)


# -- analytic footprints ------------------------------------------------------------------------

def projected_hull(mesh: trimesh.Trimesh, pose: Pose, sun: Sun) -> np.ndarray:
    """Convex hull (M, 2) of the posed mesh's vertices projected along the light onto z = 0."""
    v = np.asarray(posed_mesh(mesh, pose).vertices)
    s = sun_vector(sun)
    ground = v[:, :2] - (v[:, 2] / s[2])[:, None] * s[:2]
    return ground[ConvexHull(ground).vertices]


def polygon_mask(poly: np.ndarray, grid: GroundGrid) -> np.ndarray:
    return Path(poly).contains_points(grid.pixel_centres().reshape(-1, 3)[:, :2]).reshape(grid.height,
                                                                                          grid.width)


FOOTPRINT_SCENES = [
    ("box", Sun(140.0, 35.0), Pose(position=(0.2, -0.1, 0.0), rotation_deg=(0.0, 0.0, 27.0))),
    ("box", Sun(260.0, 62.0), Pose(position=(0.0, 0.0, 0.3), rotation_deg=(8.0, -5.0, 71.0))),
    ("cylinder", Sun(140.0, 35.0), Pose(position=(0.2, -0.1, 0.0))),
    ("cylinder", Sun(30.0, 50.0), Pose(position=(-0.3, 0.2, 0.4))),
]


def footprint_mesh(kind):
    return standing_box((0.7, 0.4, 1.1)) if kind == "box" else standing_cylinder()


@pytest.mark.parametrize("kind,sun,pose", FOOTPRINT_SCENES, ids=[f"{s[0]}-{i}" for i, s in enumerate(FOOTPRINT_SCENES)])
def test_box_and_cylinder_shadows_match_their_analytic_footprints(kind, sun, pose):
    mesh = footprint_mesh(kind)
    mdl = point_model(mesh)
    hull = projected_hull(mesh, pose, sun)  # a convex occluder's shadow: the hull of its projection
    centre = hull.mean(0)
    grid = GroundGrid.around(tuple(centre), 1.3 * float(np.ptp(hull, axis=0).max()) + 0.5, 128)
    truth = polygon_mask(hull, grid)
    dist_px = distance_to_other_class(truth)
    for k in (0.0, 0.02):
        alpha = alpha_map(mdl, k, sun, pose, grid)
        wrong = (alpha >= 0.5) != truth
        assert not np.any(wrong & (dist_px > 1.5)), f"k = {k}: {int(np.sum(wrong & (dist_px > 1.5)))} px off"
    if kind == "cylinder":
        # The smooth cylinder: two circles of radius r, the base's and the top's projection,
        # joined by tangents. Its area pi r^2 + 2 r D; the 64-gon is 0.16 % smaller.
        r, h = 0.25, 1.2
        s = sun_vector(sun)
        shift = np.linalg.norm(s[:2]) / s[2] * h  # D: how far the top circle's projection lies
        area_analytic = np.pi * r ** 2 + 2 * r * shift
        area_model = np.sum(alpha_map(mdl, 0.0, sun, pose, grid) > 0.5) * grid.pixel_m ** 2
        assert abs(area_model - area_analytic) < 0.03 * area_analytic


# -- simple properties --------------------------------------------------------------------------

@given(mesh=st.sampled_from(["pillar", "ball"]),
       profile=st.sampled_from(["linear", "disk"]),
       rule=st.sampled_from(["edge", "paper"]),
       k=st.floats(0.0, 0.08), rho=st.floats(0.0, 1.0),
       azimuth=st.floats(0.0, 360.0), elevation=st.floats(10.0, 85.0),
       rot_z=st.floats(-180.0, 180.0), x=st.floats(-0.5, 0.5))
def test_alpha_in_unit_interval_and_rho_only_scales(mesh, profile, rule, k, rho, azimuth, elevation, rot_z, x):
    mdl = builtin_model(mesh, rule, profile)
    sun, pose = Sun(azimuth, elevation), Pose(position=(x, 0.0, 0.0), rotation_deg=(0.0, 0.0, rot_z))
    s = sun_vector(sun)
    reach = min(3.0 / np.tan(np.radians(elevation)), 6.0)
    centre = (x - 0.5 * reach * s[0] / np.linalg.norm(s[:2]), -0.5 * reach * s[1] / np.linalg.norm(s[:2]))
    grid = GroundGrid.around(centre, reach + 1.5, 48)
    plan = fixed_shape_grid_plan(mdl, sun, pose, grid, k)  # one compile for all examples
    shading = np.asarray(mdl.ground_map(ShadowParams(k, rho), sun, pose, grid, plan=plan))
    assert np.all(np.isfinite(shading))
    assert shading.min() >= rho - 1e-12 and shading.max() <= 1.0 + 1e-12
    other = np.asarray(mdl.ground_map(ShadowParams(k, 0.5 * rho), sun, pose, grid, plan=plan))
    if rho < 1.0:
        # alpha does not depend on rho: shade = 1 - alpha (1 - rho).
        # Compared as 1 - shade = alpha (1 - rho): dividing by 1 - rho would amplify rounding
        # without bound as rho -> 1.
        np.testing.assert_allclose(1 - shading, (1 - other) * (1 - rho) / (1 - 0.5 * rho), atol=1e-9)
    else:
        np.testing.assert_array_equal(shading, np.ones_like(shading))


@pytest.mark.parametrize("name", ["pillar", "dragon"])
def test_rho_one_is_an_image_without_shadow(name):
    sun, pose = Sun(135.0, 40.0), Pose()
    grid = GroundGrid.around((-0.8, 0.8), 3.0, 64)
    shading = np.asarray(builtin_model(name).ground_map(ShadowParams(0.03, 1.0), sun, pose, grid))
    np.testing.assert_array_equal(shading, np.ones((64, 64)))
    points = grid.pixel_centres().reshape(-1, 3)[::5]
    values = np.asarray(builtin_model(name).at_points(ShadowParams(0.03, 1.0), sun, pose, points))
    np.testing.assert_array_equal(values, np.ones(len(points)))


@pytest.mark.parametrize("name,k", [("pillar", 0.0), ("pillar", 0.03), ("ball", 0.03), ("dragon", 0.02)])
@pytest.mark.parametrize("shift_px", [(7, -3), (-12, 5)])
def test_moving_the_object_moves_the_shadow(name, k, shift_px):
    """Translate by (dx, dy, 0), a whole number of pixels: the map shifts by exactly that many pixels."""
    mdl = builtin_model(name)
    sun = Sun(150.0, 45.0)
    grid = GroundGrid.around((-0.4, 0.9), 3.2, 96)
    dc, dr = shift_px
    dx, dy = dc * grid.pixel_m, -dr * grid.pixel_m  # columns go east, rows go south
    base = alpha_map(mdl, k, sun, Pose(rotation_deg=(0.0, 0.0, 20.0)), grid)
    moved = alpha_map(mdl, k, sun, Pose(position=(dx, dy, 0.0), rotation_deg=(0.0, 0.0, 20.0)), grid)
    h, w = base.shape
    src = base[max(0, -dr):h - max(0, dr), max(0, -dc):w - max(0, dc)]
    dst = moved[max(0, dr):h - max(0, -dr), max(0, dc):w - max(0, -dc)]
    assert np.sum(src > 0.5) > 100
    diff = np.abs(src - dst)
    assert diff.max() < 1e-6, f"{int(np.sum(diff > 1e-6))} pixels differ, worst by {diff.max():.3g}"


# -- the penumbra's width --------------------------------------------------------------------------

def ramp_width(xs: np.ndarray, alpha: np.ndarray, at: float = 0.0) -> float:
    """Width over which alpha goes 0 -> 1, from a line fit to the ramp's interior (10-90 %).

    Only the run of samples with alpha in (0.1, 0.9) that is nearest ``at`` is used,
    so another edge's ramp further along the profile does not enter the fit.
    """
    inner = (alpha > 0.1) & (alpha < 0.9)
    assert inner.any(), "no sample inside the ramp"
    idx = np.nonzero(inner)[0]
    runs = np.split(idx, np.nonzero(np.diff(idx) > 1)[0] + 1)
    run = min(runs, key=lambda r: np.min(np.abs(xs[r] - at)))
    assert len(run) >= 6, "too few samples inside the ramp"
    slope = np.polyfit(xs[run], alpha[run], 1)[0]
    return 1.0 / abs(slope)


def expected_ground_width(p: np.ndarray, t: np.ndarray, sun: Sun, k: float, across: np.ndarray,
                          direction: np.ndarray | None = None) -> float:
    """The model's ground width across an edge at its point p (tangent t): project p along
    L + k N and L - k N (N = n = unit t x L by default) and measure along the ground direction
    ``across`` perpendicular to the projected edge."""
    light = -sun_vector(sun)
    n = np.cross(t, light)
    n /= np.linalg.norm(n)
    if direction is not None:
        n = direction
    ends = []
    for sign in (1.0, -1.0):
        d = light + sign * k * n
        d /= np.linalg.norm(d)
        ends.append(p[:2] - p[2] / d[2] * d[:2])
    return abs(float(np.dot(ends[0] - ends[1], across)))


@pytest.mark.parametrize("profile", ["linear", "disk"])
def test_side_edge_penumbra_widens_with_distance_as_2kd(profile):
    """Pillar turned 30 deg, sun due south: the shadow runs north and its sides are the shadows of
    two vertical corner edges. Across them (along x) the ramp is 2 k d wide, d = h / sin E being the
    distance along the light from the edge point at height h."""
    k, elevation = 0.03, 45.0
    mdl = builtin_model("pillar", "edge", profile)
    sun, pose = Sun(180.0, elevation), Pose(rotation_deg=(0.0, 0.0, 30.0))
    corner = np.array([np.cos(np.radians(-15.0)), np.sin(np.radians(-15.0))]) * 0.1 * np.sqrt(2)
    widths = {}
    for h in (0.8, 2.4):
        y = corner[1] + h / np.tan(np.radians(elevation))
        xs = corner[0] + np.linspace(-0.2, 0.2, 801) + 1.1e-5
        points = np.c_[xs, np.full_like(xs, y), np.zeros_like(xs)]
        shading = np.asarray(mdl.at_points(ShadowParams(k, 0.0), sun, pose, points))
        alpha = 1.0 - shading
        if profile == "linear":
            widths[h] = ramp_width(xs, alpha, at=corner[0])
        else:
            # Same end points as the linear ramp: first and last x with alpha strictly inside (0, 1).
            near = np.abs(xs - corner[0]) < 0.15  # this edge's ramp only (the other side is 0.27 m off)
            inner = xs[near & (alpha > 1e-12) & (alpha < 1 - 1e-12)]
            widths[h] = inner.max() - inner.min()
        expected = 2 * k * h / np.sin(np.radians(elevation))
        independent = expected_ground_width(np.array([corner[0], corner[1], h]), np.array([0.0, 0.0, 1.0]),
                                            sun, k, np.array([1.0, 0.0]))
        assert abs(independent - expected) < 0.01 * expected  # small-k geometry agrees with 2 k d
        assert abs(widths[h] - expected) < 0.03 * expected + 0.001, (
            f"h = {h}: ramp {widths[h]:.4f} m, model says 2 k d = {expected:.4f} m")
    assert abs(widths[2.4] / widths[0.8] - 3.0) < 0.1


def test_top_edge_penumbra_is_stretched_on_the_ground():
    """A long box's top edge facing away from the sun: the ground width across it is 2 k d times
    the stretch 1 / sin E (the across-plane meets the ground obliquely); twice as high, twice as wide."""
    k, elevation = 0.02, 40.0
    sun = Sun(180.0, elevation)  # light travels north; the far top edge is the one at +y
    widths = []
    for height in (0.8, 1.6):
        mdl = point_model(standing_box((2.0, 0.3, height)))
        pose = Pose(rotation_deg=(0.0, 0.0, 3.0))  # off the exact side-on tie of the end faces
        edge_mid = np.array([0.0, 0.15, height]) @ np.asarray(pose.rotation).T
        t = np.array([1.0, 0.0, 0.0]) @ np.asarray(pose.rotation).T
        across = np.array([-t[1], t[0]])
        s = sun_vector(sun)
        ground_mid = edge_mid[:2] + edge_mid[2] / s[2] * (-s[:2])
        offsets = np.linspace(-0.25, 0.25, 1001) + 1.3e-5
        pts = ground_mid + offsets[:, None] * across
        shading = np.asarray(mdl.at_points(ShadowParams(k, 0.0), sun, pose, np.c_[pts, np.zeros(len(pts))]))
        width = ramp_width(offsets, 1.0 - shading)
        expected = expected_ground_width(edge_mid, t, sun, k, across)
        d = height / np.sin(np.radians(elevation))
        stretch_formula = 2 * k * d / np.sin(np.radians(elevation)) * abs(np.dot(across, [0.0, 1.0]))
        assert abs(expected - stretch_formula) < 0.02 * stretch_formula
        assert abs(width - expected) < 0.03 * expected, f"ramp {width:.4f} m, model {expected:.4f} m"
        widths.append(width)
    assert abs(widths[1] / widths[0] - 2.0) < 0.06


def test_disk_profile_has_the_linear_end_points():
    sun, pose, params = Sun(160.0, 35.0), Pose(rotation_deg=(0.0, 0.0, 11.0)), ShadowParams(0.03, 0.2)
    grid = GroundGrid.around((-0.7, 2.0), 4.0, 96)
    lin_model, disk_model = builtin_model("pillar", "edge", "linear"), builtin_model("pillar", "edge", "disk")
    plan = lin_model.plan_grid(sun, pose, grid, range_k_max=0.03)
    lin = (1 - np.asarray(lin_model.ground_map(params, sun, pose, grid, plan=plan))) / 0.8
    disk = (1 - np.asarray(disk_model.ground_map(params, sun, pose, grid, plan=plan))) / 0.8
    ramp = (lin > 1e-9) & (lin < 1 - 1e-9)
    assert ramp.sum() > 50
    np.testing.assert_allclose(disk[lin <= 1e-12], 0.0, atol=1e-12)
    np.testing.assert_allclose(disk[lin >= 1 - 1e-12], 1.0, atol=1e-12)
    assert np.all((disk[ramp] > 0) & (disk[ramp] < 1))
    # Behind one edge both are monotone in the same direction and meet at the middle:
    # sign(disk - 1/2) = sign(lin - 1/2). (At the outline's corners the two lights' wedge masses
    # differ, so the half-edge profiles are compared with the corners off.)
    lin = (1 - np.asarray(lin_model.with_options(corners=False).ground_map(params, sun, pose, grid, plan=plan))) / 0.8
    disk = (1 - np.asarray(disk_model.with_options(corners=False).ground_map(params, sun, pose, grid,
                                                                             plan=plan))) / 0.8
    ramp = (lin > 1e-9) & (lin < 1 - 1e-9)
    assert np.all(np.sign(np.round(disk[ramp] - 0.5, 9)) == np.sign(np.round(lin[ramp] - 0.5, 9)))


@pytest.mark.parametrize("rot_z,expected_ratio", [(30.0, np.cos(np.radians(15.0))),
                                                  (1.0, np.cos(np.radians(44.0)))])
def test_paper_rule_reads_N_dot_n_of_the_edge_rule_at_a_box_corner(rot_z, expected_ratio):
    """Paper rule at a pillar's vertical 90-degree corner: N = normalize(N1 + N2) is diagonal, and only
    N . n of the expansion goes across the shadow edge (0.72 near side-on, NOTES: 'about 0.71')."""
    k, elevation = 0.03, 45.0
    sun, pose = Sun(180.0, elevation), Pose(rotation_deg=(0.0, 0.0, rot_z))
    # The silhouette corner on the +x side: between the faces facing 300+rot and 30+rot... i.e. the
    # corner whose diagonal points at -45 + rot_z degrees.
    ang = np.radians(-45.0 + rot_z)
    corner = np.array([np.cos(ang), np.sin(ang)]) * 0.1 * np.sqrt(2)
    h = 1.6
    y = corner[1] + h / np.tan(np.radians(elevation))
    xs = corner[0] + np.linspace(-0.2, 0.2, 1601) + 1.1e-5
    points = np.c_[xs, np.full_like(xs, y), np.zeros_like(xs)]
    widths = {}
    for rule in ("edge", "paper"):
        shading = np.asarray(builtin_model("pillar", rule).at_points(ShadowParams(k, 0.0), sun, pose, points))
        widths[rule] = ramp_width(xs, 1.0 - shading, at=corner[0])
    assert abs(widths["paper"] / widths["edge"] - expected_ratio) < 0.02, widths
    if rot_z == 1.0:
        assert abs(widths["paper"] / widths["edge"] - 0.71) < 0.03


def test_paper_rule_equals_edge_rule_on_a_cylinder_side():
    """On a finely faceted cylinder N . n ~ 1: both rules give the same penumbra across its side."""
    k, elevation = 0.03, 40.0
    cyl = standing_cylinder(radius=0.25, height=1.2, sections=128)
    sun, pose = Sun(180.0, elevation), Pose()
    h = 0.9
    y = h / np.tan(np.radians(elevation))
    xs = 0.25 + np.linspace(-0.15, 0.15, 1201) + 1.1e-5
    points = np.c_[xs, np.full_like(xs, y), np.zeros_like(xs)]
    widths = {}
    for rule in ("edge", "paper"):
        shading = np.asarray(point_model(cyl, rule=rule).at_points(ShadowParams(k, 0.0), sun,
                                                                                 pose, points))
        widths[rule] = ramp_width(xs, 1.0 - shading, at=0.25)
    expected = 2 * k * h / np.sin(np.radians(elevation))
    assert abs(widths["edge"] - expected) < 0.04 * expected
    assert abs(widths["paper"] / widths["edge"] - 1.0) < 0.03, widths


# -- consistency between outputs ------------------------------------------------------------------

CONSISTENCY_SCENES = [
    ("pillar", Sun(160.0, 30.0), GroundGrid.around((-0.9, 2.4), 6.0, 64)),
    ("ball", Sun(160.0, 45.0), GroundGrid.around((-0.9, 1.2), 3.0, 64)),
    ("dragon", Sun(135.0, 40.0), GroundGrid.around((-0.5, 0.5), 3.0, 64)),
]


def expected_failure(scenes, failing: dict[str, str]):
    """CONSISTENCY_SCENES as pytest params, with a strict xfail (reason given) on the failing names."""
    return [pytest.param(*s, id=s[0], marks=pytest.mark.xfail(reason=failing[s[0]], strict=True))
            if s[0] in failing else pytest.param(*s, id=s[0]) for s in scenes]


# The discrete plan depends on its raster's resolution: a ground map rasters at its own pixel
# (94 mm for the pillar here), at_points at the points' extent / 1024 (5.9 mm), so the two plans
# can disagree where a band or a candidate edge is decided near a raster pixel.
MAP_VS_POINTS_FAILURES = {
    "pillar": "known bug: plan_points sizes a point's penumbra band by its nearest outline edge "
              "(a 0.37 m wedge) while near the shadow's tip a wider neighbouring top edge (0.72 m) "
              "governs; at_points' 5.9 mm raster leaves 2 tip pixels out of the band (lit, 1.0) that "
              "the 94 mm map's wider margin keeps (0.94)",
    "ball": "known limitation: 1 pixel where the map's 47 mm raster and at_points' 2.9 mm raster pick "
            "different candidate edges among the ball's short silhouette edges (0.405 vs 0.407)",
    "dragon": "known limitation: the dragon's gaps smaller than the map's 47 mm raster pixel are seen "
              "by at_points' finer raster and not by the map (347 pixels, up to 0.48)",
}
CAMERA_VS_MAP_FAILURES = {
    "dragon": "known limitation: the camera's plan rasters at its own ground footprint, finer than the "
              "map's 47 mm pixel, and sees gaps of the dragon that the map does not (148 pixels, up "
              "to 0.44)",
}


@pytest.mark.parametrize("name,sun,grid", expected_failure(CONSISTENCY_SCENES, MAP_VS_POINTS_FAILURES))
def test_ground_map_equals_values_at_its_pixel_centres(name, sun, grid):
    mdl = builtin_model(name)
    params, pose = ShadowParams(0.03, 0.3), Pose(rotation_deg=(0.0, 0.0, 17.0))
    ground = np.asarray(mdl.ground_map(params, sun, pose, grid))
    points = np.asarray(mdl.at_points(params, sun, pose, grid.pixel_centres().reshape(-1, 3)))
    diff = np.abs(ground - points.reshape(ground.shape))
    assert np.sum((ground > 0.31) & (ground < 0.99)) > 50
    assert diff.max() < 1e-6, (f"{int(np.sum(diff > 1e-6))} pixels differ, worst {diff.max():.3f}: "
                               f"map {ground.ravel()[np.argmax(diff)]:.4f} vs points "
                               f"{points[np.argmax(diff)]:.4f}")


@pytest.mark.parametrize("name,sun,grid", expected_failure(CONSISTENCY_SCENES, CAMERA_VS_MAP_FAILURES))
def test_camera_looking_straight_down_sees_the_ground_map(name, sun, grid):
    mdl = builtin_model(name)
    params, pose = ShadowParams(0.03, 0.3), Pose(rotation_deg=(0.0, 0.0, 17.0))
    centre = grid.to_world((grid.width - 1) / 2, (grid.height - 1) / 2)
    height = 20.0
    fov = 2 * np.degrees(np.arctan(grid.width * grid.pixel_m / 2 / height))
    camera = look_at_camera((centre[0], centre[1], height), (centre[0], centre[1], 0.0), grid.width,
                            grid.height, fov)
    render = mdl.camera_image(params, sun, pose, camera)
    np.testing.assert_allclose(render.ground_points[..., :2], grid.pixel_centres()[..., :2], atol=1e-9)
    seen = render.ground_valid & ~render.object_mask
    assert seen.sum() > 0.5 * seen.size and render.object_mask.sum() > 0
    assert np.all(np.isnan(np.asarray(render.shading)[~seen]))
    ground = np.asarray(mdl.ground_map(params, sun, pose, grid))
    diff = np.abs(np.asarray(render.shading)[seen] - ground[seen])
    assert diff.max() < 1e-6, f"{int(np.sum(diff > 1e-6))} pixels differ, worst {diff.max():.3f}"


@pytest.mark.parametrize("rule", ["edge", "paper"])
@pytest.mark.parametrize("k", [0.0, 0.02])
def test_box_lit_side_on_does_not_depend_on_the_tie_break(rule, k):
    """Sun due east on an axis-aligned box: two faces have n . L = 0 exactly. Turning the sun by
    +-1e-6 degrees breaks the tie either way; the shadow must not change (docs/formats.md)."""
    mdl = point_model(standing_box((0.6, 0.4, 1.0)), rule=rule)
    grid = GroundGrid(0.0213, (-2.6, 0.61), 96, 64)  # pixel centres off the shadow's sides y = +-0.2
    maps = [alpha_map(mdl, k, Sun(az, 35.0), Pose(), grid) for az in (90.0, 90.0 - 1e-6, 90.0 + 1e-6)]
    assert np.sum(maps[0] > 0.5) > 200
    for other in maps[1:]:
        if k == 0.0:
            np.testing.assert_array_equal(other, maps[0])
        else:
            assert np.abs(other - maps[0]).max() < 1e-4
