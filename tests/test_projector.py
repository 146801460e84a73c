"""The slide projector and the scene renderer with lights (docs/projector.md).

- A projector's shadow on a plane agrees with ray casting (trimesh) to within a pixel;
  no acne on the lit side of a ball, its far side dark.
- Projective texture mapping: a slide pixel lands where the projector's camera puts it;
  the footprint of a projector looking straight down; cosine and inverse-square falloff.
- Slides: the spotlight, the sine grid's amplitude and frequency (FFT), images, bad input.
- Visibility: the z-buffer's points lie on the faces they name; it agrees with the
  renderer's object mask.
- The scene image on open ground equals the model's camera image (SceneLights.from_rho);
  gradients in k, the light levels and the sun against central differences (float64);
  the float32 path.
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
from PIL import Image
from scipy import ndimage

import softshadow as ss
from softshadow import (GroundGrid, Pose, Projector, SceneLights, ShadowParams, SlideError, SoftShadowModel, Sun,
    builtin_mesh, load_slide, look_at_camera, prepare_scene, render_scene, shade_scene, sine_slide,
    slide_from_text, spot_slide)
from softshadow.internal import GROUND, NOTHING, Surface, object_mask, projector_shadow_map, visible_surfaces


@functools.cache
def model_of(name: str) -> SoftShadowModel:
    # The geometric model (pixel centres, no hidden sky), as the scene image samples it.
    return SoftShadowModel.from_mesh(name, footprint=False, hidden_sky=False)


def _within_a_pixel(mine: np.ndarray, truth: np.ndarray) -> tuple[int, int]:
    """(pixels that differ, of which farther than one pixel from the truth's outline)."""
    outline = truth ^ ndimage.binary_erosion(truth)
    outline |= ndimage.binary_dilation(truth) ^ truth
    near = ndimage.binary_dilation(outline, structure=np.ones((3, 3), bool))
    diff = mine ^ truth
    return int(diff.sum()), int((diff & ~near).sum())


# -- shadows -------------------------------------------------------------------------------------
@pytest.mark.parametrize("mesh, rotation, position, target", [
    ("pillar", (0.0, 0.0, 20.0), (2.0, -1.5, 4.0), (0.0, 0.0, 0.5)),
    ("pillar", (10.0, 0.0, 35.0), (-1.5, 2.5, 3.6), (0.0, 0.0, 1.0)),
    ("ball", (0.0, 0.0, 0.0), (1.0, 1.2, 4.5), (0.0, 0.0, 1.0)),
    ("dragon", (0.0, 0.0, 60.0), (-2.0, -2.5, 3.5), (0.0, 0.0, 0.4)),
])
def test_projector_shadow_on_a_plane_agrees_with_ray_casting(mesh, rotation, position, target):
    surf = Surface.from_trimesh(builtin_mesh(mesh), rotation_deg=rotation)
    proj = Projector(position, target, spot_slide(64), fov_deg=70.0, shadow_px=512)
    smap = projector_shadow_map(proj, surf.vertices, surf.faces)
    grid = GroundGrid.around((-0.5 * position[0], -0.5 * position[1]), 4.0, 160)
    pts = grid.pixel_centres().reshape(-1, 3)
    normals = np.tile([0.0, 0.0, 1.0], (len(pts), 1))
    mine = smap.occluded(pts, normals).reshape(160, 160)
    tm = trimesh.Trimesh(surf.vertices, surf.faces, process=False)
    to_proj = proj.position - pts
    # Every occluder lies below the projector here, so any hit along the ray towards it counts.
    truth = tm.ray.intersects_any(pts + 1e-7 * to_proj, to_proj).reshape(160, 160)
    under = object_mask(model_of(mesh).occluder, Pose(rotation_deg=rotation), grid)  # hidden by the object
    mine, truth = mine & ~under, truth & ~under
    assert truth.sum() > 200, "the test scene must throw a shadow"
    differ, far = _within_a_pixel(mine, truth)
    assert far == 0, f"{far} of {differ} differing pixels lie farther than a pixel from the ray-cast outline"
    assert differ < 0.1 * truth.sum()


def test_projector_shadow_in_a_camera_image_agrees_with_ray_casting():
    """The whole pipeline: the camera's z-buffer, the projector's light with a clear slide; the
    ground pixels it leaves dark against rays from the same ground points to the projector."""
    model = model_of("dragon")
    cam = look_at_camera((2.5, -4.0, 3.0), (0.0, 0.5, 0.3), 160, 120, 50.0)
    proj = Projector((-2.0, -2.5, 3.5), (0.0, 0.0, 0.4), np.ones((64, 64, 3)), fov_deg=80.0, shadow_px=768)
    setup = prepare_scene(cam, model, Pose(), None, [proj])
    vis = setup.visible
    ground = (vis.surface.ravel()[vis.pixel] == GROUND)
    dark = np.zeros(vis.shape, bool)
    dark.ravel()[vis.pixel[ground]] = setup.projector_light[ground, 0] == 0
    tm = trimesh.Trimesh(*(np.asarray(a) for a in (ss.internal.posed_vertices(model.occluder, Pose())[0],
                                                   model.occluder.faces)), process=False)
    p = vis.points[ground]
    truth = np.zeros(vis.shape, bool)
    truth.ravel()[vis.pixel[ground]] = tm.ray.intersects_any(p + 1e-7 * (proj.position - p), proj.position - p)
    on_ground = np.zeros(vis.shape, bool)  # ground inside the projector's beam
    on_ground.ravel()[vis.pixel[ground]] = proj.slide_colour(p)[:, 0] > 0
    assert truth.sum() > 300 and on_ground.sum() > 0.5 * ground.sum()
    differ, far = _within_a_pixel(dark & on_ground, truth & on_ground)
    assert far == 0, f"{far} of {differ} differing ground pixels lie farther than a pixel from the outline"
    assert differ < 0.1 * truth.sum()


def test_projector_lit_side_of_a_ball_has_no_acne_and_its_far_side_is_dark():
    mesh = builtin_mesh("ball")
    surf = Surface.from_trimesh(mesh)
    proj = Projector((3.0, -2.0, 3.5), (0.0, 0.0, 1.5), spot_slide(64), fov_deg=40.0, shadow_px=256)
    smap = projector_shadow_map(proj, surf.vertices, surf.faces)
    pts, face = trimesh.sample.sample_surface(mesh, 4000, seed=1)
    normals = mesh.face_normals[face]
    towards = np.einsum("ij,ij->i", normals, proj.position - pts) / np.linalg.norm(proj.position - pts, axis=1)
    occ = smap.occluded(pts, normals)
    lit_side, far_side = towards > 0.05, towards < -0.05
    assert not occ[lit_side].any(), f"{occ[lit_side].sum()} lit points shadowed (acne)"
    assert occ[far_side].all()


@pytest.mark.parametrize("position", [(3.0, -2.0, 3.5), (0.3, 0.2, 1.2)])  # the second cuts faces at its plane
def test_projector_map_faces_are_the_shadow_maps_own(position):
    """The map's per-face arrays, made in one compiled pass, equal ``shadow_map``'s triangles,
    planes and scale and the lookup's packed rows computed from them (bit for bit)."""
    from softshadow.clip import clip_near
    from softshadow.projector import NEAR_M
    from softshadow.shadowmap import shadow_map
    surf = Surface.from_trimesh(builtin_mesh("ball"))
    proj = Projector(position, (0.0, 0.0, 0.5), spot_slide(32), fov_deg=60.0, shadow_px=64)
    pm = projector_shadow_map(proj, surf.vertices, surf.faces, scratch=ss.internal.Scratch())
    world, faces = surf.vertices, surf.faces
    if not pm.faces_as_given:
        world, faces, _ = clip_near(world, proj.image_coordinates(world)[1], faces, NEAR_M)
    ab, z = proj.image_coordinates(world)
    ref = shadow_map(pm.smap.grid, np.column_stack([ab[:, 0], -ab[:, 1]]), -1.0 / np.maximum(z, NEAR_M), faces)
    for name in ("depth", "face_id", "plane", "triangle"):
        np.testing.assert_array_equal(getattr(pm.smap, name), getattr(ref, name))
    assert pm.smap.scale == ref.scale
    packed = pm._packed_faces.copy()
    del pm.__dict__["_packed_faces"]  # recomputed by the property from the triangles and planes
    np.testing.assert_array_equal(pm._packed_faces, packed)
    assert np.all(pm.smap.slope >= 0) and np.all(np.isfinite(pm.smap.slope))


def test_no_occluder_in_front_of_the_projector_means_no_shadow():
    surf = Surface.from_trimesh(builtin_mesh("pillar"))
    proj = Projector((0.0, -3.0, 1.0), (0.0, -6.0, 0.0), spot_slide(32))  # looking away
    smap = projector_shadow_map(proj, surf.vertices, surf.faces)
    pts = GroundGrid.around((0.0, -6.0), 4.0, 40).pixel_centres().reshape(-1, 3)
    assert not smap.occluded(pts).any()


# -- projective texture mapping ---------------------------------------------------------------------
def test_a_slide_pixel_lands_where_the_projector_camera_puts_it():
    rng = np.random.default_rng(3)
    slide = rng.uniform(0.0, 1.0, (48, 64, 3))
    proj = Projector((0.3, -0.2, 2.5), (0.5, 0.4, 0.0), slide, fov_deg=50.0, up=(0.0, 1.0, 0.0))
    cam = proj.camera
    # Ground points seen at the slide's pixel centres: their colour is that pixel's.
    rows, cols = np.mgrid[2:46:5, 3:61:7]
    ground, valid = cam.ground_points(cols.ravel(), rows.ravel())
    assert valid.all()
    got = proj.slide_colour(ground)
    # The slide is read in float32 (its values to 6e-8).
    np.testing.assert_allclose(got, slide[rows.ravel(), cols.ravel()], atol=1e-7)


def test_straight_down_projector_footprint_is_two_h_tan_half_fov():
    h, fov = 2.0, 40.0
    proj = Projector((0.0, 0.0, h), (0.0, 0.0, 0.0), np.ones((100, 100, 3)), fov_deg=fov)
    half = h * np.tan(np.deg2rad(fov / 2))
    xs = np.array([half * 0.99, half * 1.01])
    pts = np.column_stack([xs, np.zeros(2), np.zeros(2)])
    np.testing.assert_allclose(proj.slide_colour(pts)[:, 0], [1.0, 0.0])
    behind = proj.slide_colour(np.array([[0.0, 0.0, 3.0]]))
    assert np.all(behind == 0)


def test_irradiance_follows_the_cosine_and_the_inverse_square():
    proj = Projector((0.0, 0.0, 2.0), (0.0, 0.0, 0.0), np.full((8, 8, 3), 0.5), fov_deg=60.0, intensity=2.0)
    at_target = proj.irradiance([[0.0, 0.0, 0.0]], [[0.0, 0.0, 1.0]])
    np.testing.assert_allclose(at_target, [[1.0, 1.0, 1.0]])
    tilted = proj.irradiance([[0.0, 0.0, 0.0]], [[np.sin(np.pi / 3), 0.0, np.cos(np.pi / 3)]])
    np.testing.assert_allclose(tilted, 0.5 * at_target)
    nearer = proj.irradiance([[0.0, 0.0, 1.0]], [[0.0, 0.0, 1.0]])
    np.testing.assert_allclose(nearer, 4.0 * at_target)
    facing_away = proj.irradiance([[0.0, 0.0, 0.0]], [[0.0, 0.0, -1.0]])
    assert np.all(facing_away == 0)
    flat = Projector((0.0, 0.0, 2.0), (0.0, 0.0, 0.0), np.full((8, 8, 3), 0.5), falloff="none")
    np.testing.assert_allclose(flat.irradiance([[0.0, 0.0, 1.0]]), flat.irradiance([[0.0, 0.0, 0.0]]))


@pytest.mark.parametrize("kwargs, message", [
    (dict(position=(0, 0, 1), target=(0, 0, 1)), "target must differ"),
    (dict(fov_deg=0.0), "fov_deg"),
    (dict(fov_deg=175.0), "fov_deg"),
    (dict(intensity=-1.0), "intensity"),
    (dict(falloff="linear"), "falloff"),
    (dict(position=(0, np.nan, 1)), "position"),
    (dict(slide=np.ones((4, 4, 2))), "slide"),
    (dict(slide=-np.ones((4, 4))), "slide"),
    (dict(shadow_px=4), "shadow_px"),
])
def test_bad_projectors_are_refused_with_the_reason(kwargs, message):
    args = dict(position=(0, 0, 2), target=(0, 0, 0), slide=np.ones((4, 4, 3)))
    args.update(kwargs)
    with pytest.raises(ValueError, match=message):
        Projector(**args)


# -- slides -------------------------------------------------------------------------------------------
def test_spot_slide_is_a_soft_disk():
    s = spot_slide(101, radius=0.4, softness=0.1)[..., 0]
    assert s.shape == (101, 101)
    assert s[50, 50] == 1.0 and s[0, 0] == 0.0 and s[50, 0] == 0.0
    row = s[50, 50:]
    assert np.all(np.diff(row) <= 1e-12), "the beam falls off monotonically from the centre"
    r = np.abs((np.arange(101) + 0.5) / 101 - 0.5)[50:]
    assert np.all(row[r <= 0.3] == 1.0) and np.all(row[r >= 0.4] == 0.0)


@pytest.mark.parametrize("frequency, amplitude", [(4.0, 1.0), (15.0, 1.0), (15.0, 0.5), (7.0, 0.25)])
def test_sine_slide_has_its_frequency_and_amplitude(frequency, amplitude):
    size = 256
    slide = sine_slide(frequency, amplitude, size)[..., 0]
    spot = spot_slide(size)[..., 0]
    core = spot == 1.0
    mod = slide[core]
    np.testing.assert_allclose(mod.max(), 1.0, atol=0.02)
    np.testing.assert_allclose(mod.min(), 1.0 - amplitude, atol=0.02)
    # The modulation alone (divided by the spot inside the beam): its strongest non-zero frequency.
    m = np.where(spot > 0.5, slide / np.maximum(spot, 1e-9), 1.0 - amplitude / 2)
    spectrum = np.abs(np.fft.rfft(m.mean(0) - m.mean()))
    assert int(np.argmax(spectrum[1:]) + 1) == int(frequency)


def test_the_paper_slides_and_frequency_zero_is_the_spotlight():
    assert ss.PAPER_SLIDES == ((1.0, 0.0), (1.0, 4.0), (1.0, 15.0), (0.5, 15.0))
    np.testing.assert_array_equal(sine_slide(0.0, 1.0, 64), spot_slide(64))
    np.testing.assert_array_equal(slide_from_text("spot", size=64), spot_slide(64))
    np.testing.assert_array_equal(slide_from_text("sine:15:0.5", size=128), sine_slide(15, 0.5, 128))
    np.testing.assert_array_equal(slide_from_text("sine:4", size=128), sine_slide(4, 1.0, 128))


def test_image_slides_are_decoded_to_linear(tmp_path):
    rgb = np.zeros((6, 8, 3), np.uint8)
    rgb[..., 0] = 255
    rgb[2, 3] = (128, 128, 128)
    Image.fromarray(rgb).save(tmp_path / "s.png")
    s = load_slide(tmp_path / "s.png")
    assert s.shape == (6, 8, 3)
    np.testing.assert_allclose(s[0, 0], [1.0, 0.0, 0.0])
    np.testing.assert_allclose(s[2, 3], ss.srgb_to_linear(128 / 255) * np.ones(3))
    Image.fromarray(rgb[..., 1]).save(tmp_path / "grey.png")
    grey = slide_from_text("grey.png", tmp_path)
    assert grey.shape == (6, 8, 3) and grey[0, 0, 0] == 0.0
    np.testing.assert_allclose(grey[2, 3], s[2, 3])


@pytest.mark.parametrize("text, message", [
    ("sine", "sine:FREQ"), ("sine:abc", "numbers"), ("sine:4:2", "amplitude"), ("sine:-1", "frequency"),
    ("sine:400", "pixels"), ("sine:1:2:3", "sine:FREQ"), ("", "empty"), ("missing.png", "not found"),
])
def test_bad_slides_are_refused_in_one_line(text, message, tmp_path):
    with pytest.raises(SlideError, match=message) as info:
        slide_from_text(text, tmp_path)
    assert "\n" not in str(info.value)


def test_an_unreadable_slide_file_is_refused(tmp_path):
    (tmp_path / "bad.png").write_text("not an image")
    with pytest.raises(SlideError, match="cannot read"):
        load_slide(tmp_path / "bad.png")


# -- visibility ------------------------------------------------------------------------------------
def test_visible_points_lie_on_the_faces_they_name_and_match_the_object_mask():
    model = model_of("ball")
    pose = Pose((0.2, 0.1, 0.0), (0.0, 0.0, 15.0))
    cam = look_at_camera((3.0, -3.5, 2.5), (0.0, 0.0, 1.2), 120, 90, 45.0)
    surf = Surface(ss.internal.posed_vertices(model.occluder, pose)[0], model.occluder.faces, 0.5, "ball")
    vis = visible_surfaces(cam, [surf], ground_albedo=0.3)
    on_ball = (vis.surface == 0).ravel()[vis.pixel]
    assert on_ball.sum() > 500
    faces = vis.face.ravel()[vis.pixel[on_ball]]
    tri = surf.vertices[surf.faces[faces]]
    p = vis.points[on_ball]
    # On the face's plane and inside its triangle (barycentric >= -small).
    n = surf.face_normals[faces]
    np.testing.assert_allclose(np.einsum("ij,ij->i", n, p - tri[:, 0]), 0.0, atol=1e-9)
    assert np.all(np.einsum("ij,ij->i", vis.normals[on_ball], cam.centre - p) > 0), "normals face the camera"
    mask = object_mask(model.occluder, pose, cam)
    mine = vis.surface == 0
    differ, far = _within_a_pixel(mine, mask)
    assert far == 0
    ground = (vis.surface == GROUND).ravel()[vis.pixel]
    np.testing.assert_allclose(vis.points[ground][:, 2], 0.0, atol=1e-9)
    np.testing.assert_allclose(vis.albedo[ground], 0.3)


def test_near_plane_clipping_keeps_a_floor_that_passes_behind_the_camera():
    """A floor mesh of two huge triangles under a camera looking down at 45 degrees: every pixel
    below the horizon sees it (its faces reach behind the camera and are cut, not dropped), at the
    same points as the analytic ground. ``clip_near`` keeps the area and the winding."""
    floor = Surface(np.array([[-50.0, -50, 0], [50, -50, 0], [50, 50, 0], [-50, 50, 0]]),
                    np.array([[0, 1, 2], [0, 2, 3]]), 0.5, "floor")
    cam = look_at_camera((0.0, 0.0, 2.0), (0.0, 4.0, 0.0), 48, 36, 60.0)
    mesh = visible_surfaces(cam, [floor], None)
    plane = visible_surfaces(cam, [], 0.5)
    np.testing.assert_array_equal(mesh.surface == 0, plane.surface == GROUND)
    np.testing.assert_allclose(mesh.points, plane.points, atol=1e-9)
    from softshadow.clip import clip_near
    v, f, src = clip_near(floor.vertices, floor.vertices[:, 1] + 1.0, floor.faces, 0.0)  # keep y > -1
    assert set(src.tolist()) == {0, 1} and np.all(v[f][..., 1] >= -1.0 - 1e-12)
    area = 0.5 * np.linalg.norm(np.cross(v[f][:, 1] - v[f][:, 0], v[f][:, 2] - v[f][:, 0]), axis=1).sum()
    np.testing.assert_allclose(area, 100.0 * 51.0)
    assert np.all(np.cross(v[f][:, 1] - v[f][:, 0], v[f][:, 2] - v[f][:, 0])[:, 2] > 0), "winding kept"


def test_smooth_normals_follow_the_sphere_better_than_flat_faces():
    model = model_of("ball")
    surf = Surface(ss.internal.posed_vertices(model.occluder, Pose())[0], model.occluder.faces)
    cam = look_at_camera((3.0, -3.0, 3.0), (0.0, 0.0, 1.5), 96, 72, 30.0)
    errors = {}
    for smooth in (False, True):
        vis = visible_surfaces(cam, [surf], None, smooth=smooth)
        true = vis.points - np.array([0.0, 0.0, 1.5])
        true /= np.linalg.norm(true, axis=1, keepdims=True)
        errors[smooth] = np.degrees(np.arccos(np.clip(np.einsum("ij,ij->i", vis.normals, true), -1, 1)))
    assert len(errors[True]) > 1000
    np.testing.assert_allclose(np.linalg.norm(vis.normals, axis=1), 1.0)
    assert np.median(errors[True]) < 0.5 * np.median(errors[False]) and errors[True].max() < 5.0


def test_top_down_visibility_sees_the_top_of_the_object_and_nothing_beyond_the_horizon():
    model = model_of("pillar")
    surf = Surface(ss.internal.posed_vertices(model.occluder, Pose())[0], model.occluder.faces)
    grid = GroundGrid.around((0.0, 0.0), 1.0, 50)
    vis = visible_surfaces(grid, [surf], ground_albedo=0.5)
    top = (vis.surface == 0).ravel()[vis.pixel]
    np.testing.assert_allclose(vis.points[top][:, 2], 3.0)
    assert 64 <= top.sum() <= 121  # the 0.2 m square top at 2 cm pixels
    sky = visible_surfaces(look_at_camera((0.0, -5.0, 1.0), (0.0, 5.0, 1.5), 40, 30, 60.0), [surf], 0.5)
    assert (sky.surface == NOTHING).sum() > 100  # above the horizon


# -- the scene image -------------------------------------------------------------------------------------
def test_open_ground_equals_the_models_camera_image():
    model = model_of("pillar")
    sun, pose = Sun(140.0, 35.0), Pose()
    params = ShadowParams(0.02, 0.25)
    cam = look_at_camera((-3.0, -6.0, 4.0), (-1.0, 2.0, 0.0), 96, 72, 55.0)
    mine = render_scene(cam, model, pose, SceneLights.from_rho(sun, 0.02, 0.25), sun, ground_albedo=1.0,
                        range_k_max=0.02)
    ref = model.camera_image(params, sun, pose, cam, range_k_max=0.02)
    ground = mine.setup.visible.surface == GROUND
    theirs = np.asarray(ref.shading)
    both = ground & np.isfinite(theirs) & ~ref.object_mask
    assert both.sum() > 3000
    img = np.asarray(mine.image)
    np.testing.assert_allclose(img[..., 0][both], theirs[both], atol=2e-3)
    np.testing.assert_allclose(img[..., 1], img[..., 0])


def test_projector_adds_its_slide_times_the_albedo():
    model = model_of("pillar")
    cam = look_at_camera((0.0, -6.0, 5.0), (0.0, 1.0, 0.0), 64, 48, 50.0)
    slide = sine_slide(4.0, 1.0, 64)
    proj = Projector((-3.0, -3.0, 4.0), (0.0, 1.0, 0.0), slide, fov_deg=60.0)
    base = render_scene(cam, model, lights=SceneLights(ambient=0.2), object_albedo=(0.9, 0.5, 0.2),
                        ground_albedo=(0.6, 0.6, 0.6))
    lit = render_scene(cam, model, lights=SceneLights(ambient=0.2), projectors=[proj],
                       object_albedo=(0.9, 0.5, 0.2), ground_albedo=(0.6, 0.6, 0.6))
    vis = lit.setup.visible
    added = np.asarray(lit.image).reshape(-1, 3)[vis.pixel] - np.asarray(base.image).reshape(-1, 3)[vis.pixel]
    np.testing.assert_allclose(added, vis.albedo * lit.setup.projector_light, atol=1e-12)
    assert (added.max(1) > 0.05).sum() > 200
    np.testing.assert_allclose(np.asarray(base.image).reshape(-1, 3)[vis.pixel], 0.2 * vis.albedo)


@pytest.mark.parametrize("view", ["pinhole", "topdown"])
def test_supersampling_averages_the_finer_image(view):
    model = model_of("pillar")
    if view == "pinhole":
        cam = look_at_camera((3.0, -4.0, 3.0), (0.0, 0.0, 1.0), 32, 24, 50.0)
    else:
        cam = GroundGrid.around((0.0, 0.0), 1.2, 24)
    proj = Projector((-2.0, -2.0, 4.0), (0.0, 0.0, 0.5), sine_slide(4.0, 1.0, 64), fov_deg=50.0)
    one = render_scene(cam, model, lights=SceneLights(0.2), projectors=[proj])
    three = render_scene(cam, model, lights=SceneLights(0.2), projectors=[proj], supersample=3)
    assert three.image.shape == one.image.shape
    assert three.setup.visible.shape == (3 * cam.height, 3 * cam.width)
    # The centre sub-pixel of each 3 x 3 block is the pixel's own centre.
    if view == "pinhole":
        fine_cam = cam.with_size(96, 72)
    else:
        third = cam.pixel_m / 3
        fine_cam = GroundGrid(third, (cam.origin_m[0] - third, cam.origin_m[1] + third), 72, 72)
    fine = render_scene(fine_cam, model, lights=SceneLights(0.2), projectors=[proj])
    np.testing.assert_allclose(np.asarray(fine.image)[1::3, 1::3], np.asarray(one.image), atol=1e-9)
    np.testing.assert_allclose(np.asarray(three.image),
                               np.asarray(fine.image).reshape(cam.height, 3, cam.width, 3, 3).mean((1, 3)),
                               atol=1e-12)
    with pytest.raises(ValueError, match="supersample"):
        render_scene(cam, model, supersample=0)


def _gradient_scene():
    model = model_of("pillar")
    cam = look_at_camera((-5.0, -1.0, 4.0), (-1.0, 2.0, 0.0), 64, 56, 60.0)  # sees the sun shadow from the side
    proj = Projector((2.0, -3.0, 3.0), (0.0, 0.0, 1.0), spot_slide(32), fov_deg=50.0)
    return model, cam, proj


@settings(max_examples=6)  # each example plans and renders 11 images: keeps the file within ~60 s
@given(k=st.floats(0.015, 0.035), elevation=st.floats(35.0, 55.0), azimuth=st.floats(130.0, 160.0),
       ambient=st.floats(0.1, 0.5), sun_irradiance=st.floats(0.5, 2.0))
def test_scene_gradients_match_central_differences(k, elevation, azimuth, ambient, sun_irradiance):
    model, cam, proj = _gradient_scene()
    sun, pose = Sun(azimuth, elevation), Pose()
    setup = prepare_scene(cam, model, pose, sun, [proj], range_k_max=0.04)

    def image(theta):
        lights = SceneLights(theta[0], theta[1], theta[2])
        return shade_scene(setup, model, lights, Sun(theta[3], theta[4]), pose)

    theta0 = jnp.asarray([ambient, sun_irradiance, k, azimuth, elevation], jnp.float64)
    jac = np.asarray(jax.jacfwd(image)(theta0)).reshape(-1, 5)
    assert np.all(np.isfinite(jac))
    base = np.asarray(image(theta0)).reshape(-1)
    steps = np.array([1e-6, 1e-6, 1e-7, 1e-6, 1e-6])
    for i in range(5):
        e = np.zeros(5)
        e[i] = steps[i]
        plus = np.asarray(image(theta0 + e)).reshape(-1)
        minus = np.asarray(image(theta0 - e)).reshape(-1)
        fwd, bwd = (plus - base) / steps[i], (base - minus) / steps[i]
        smooth = np.abs(fwd - bwd) <= 1e-3 * np.maximum(1.0, np.abs(fwd))  # not at a ramp's kink
        assert smooth.mean() > 0.95
        central = 0.5 * (fwd + bwd)
        scale = max(float(np.abs(central[smooth]).max()), 1e-3)
        np.testing.assert_allclose(jac[smooth, i], central[smooth], atol=2e-4 * scale, rtol=1e-4,
                                   err_msg=f"parameter {i}")
    assert np.abs(jac[:, 2]).max() > 1e-2, "k moves the penumbra pixels"


@pytest.mark.parametrize("k, azimuth, elevation", [
    (0.0, 150.0, 40.0),    # no penumbra at all
    (0.02, 150.0, 1.0),    # the sun at the horizon: grazing on the ground, long shadow
    (0.02, 180.0, 40.0),   # the pillar's faces exactly edge-on to the sun (n . s = 0)
])
def test_scene_gradients_are_finite_at_hard_cases(k, azimuth, elevation):
    model, cam, proj = _gradient_scene()
    sun, pose = Sun(azimuth, elevation), Pose()
    setup = prepare_scene(cam, model, pose, sun, [proj], range_k_max=0.03)

    def image(theta):
        return shade_scene(setup, model, SceneLights(theta[0], theta[1], theta[2]), Sun(theta[3], theta[4]), pose)

    # Forward mode, as the property test: the same compiled programs.
    jac = np.asarray(jax.jacfwd(image)(jnp.asarray([0.3, 1.0, k, azimuth, elevation], jnp.float64)))
    assert np.all(np.isfinite(jac))
    grad = jac.reshape(-1, 5).sum(0)
    assert np.all(np.isfinite(grad)), grad
    assert grad[0] > 0 and grad[1] > 0  # more light, a brighter image


def test_scene_float32_path_is_close_to_float64():
    model, cam, proj = _gradient_scene()
    sun = Sun(150.0, 40.0)
    ref = np.asarray(render_scene(cam, model, None, SceneLights(0.3, 1.0, 0.02), sun, [proj]).image)
    with jax.enable_x64(False):
        r32 = render_scene(cam, model, None, SceneLights(0.3, 1.0, 0.02), Sun(150.0, 40.0), [proj])
        img32 = np.asarray(r32.image)
    assert img32.dtype == np.float32
    np.testing.assert_allclose(img32, ref, atol=2e-3)
