"""The physical renderer against analytic soft shadows, convergence, and an independent Mitsuba render."""

from __future__ import annotations

import json
import math

import numpy as np
import trimesh

from data_synth.lighting import SunSky
from datapaths import MITSUBA as MITSUBA_DIR
from data_synth.physical import shadow_reach, sky_visibility, sky_visibility_map, sun_visibility
from data_synth.receivers import PlaneReceiver, bank_terrain
from softshadow.meshes import builtin_mesh

MITSUBA = MITSUBA_DIR / "pillar-yaw30-topdown"

H = 1.0  # height of the plate's lower face


def half_plane(height=H):
    """A thin 200 m plate covering x < 0 with its lower face at z = height (a straight edge along y)."""
    plate = trimesh.creation.box(extents=[200.0, 200.0, 0.01])
    plate.apply_translation([-100.0, 0.0, height + 0.005])
    return plate


def occluded_disk_visible(u):
    u = np.clip(u, -1.0, 1.0)
    return 1.0 - (np.arccos(u) - u * np.sqrt(1.0 - u * u)) / np.pi


def edge_profile(sun, n_samples, seed=1, n_points=161, span=0.8):
    """Visibility across the plate's shadow edge on the ground and the analytic profile there."""
    el = math.radians(sun.elevation_deg)
    x_edge = -H / math.tan(el)
    width = 2 * H * math.tan(sun.radius_rad) / math.sin(el) ** 2  # perpendicular width stretched on the ground
    xs = np.linspace(x_edge - span * width, x_edge + span * width, n_points)
    pts = np.stack([xs, np.zeros_like(xs), np.zeros_like(xs)], -1)
    nrm = np.tile([0.0, 0.0, 1.0], (len(xs), 1))
    vis = sun_visibility(half_plane(), pts, nrm, sun, n_samples, np.random.default_rng(seed))
    # Seen from a ground point at x, the edge stands at elevation atan(H / -x); the disk's centre at el.
    u = (np.arctan2(H, -xs) - el) / sun.radius_rad
    return xs, vis, u, x_edge, width


def test_straight_edge_penumbra_matches_occluded_disk_profile():
    sun = SunSky(90.0, 40.0, 0.2665)
    xs, vis, u, _, _ = edge_profile(sun, 1024)
    ref = occluded_disk_visible(u)
    assert np.max(np.abs(vis - ref)) < 0.03
    assert np.sqrt(np.mean((vis - ref) ** 2)) < 0.006


def test_penumbra_width_is_2_d_tan_r_stretched_on_the_ground():
    sun = SunSky(90.0, 30.0, 0.5)
    el = math.radians(sun.elevation_deg)
    x_edge = -H / math.tan(el)
    width = 2 * H * math.tan(sun.radius_rad) / math.sin(el) ** 2
    xs = x_edge + np.array([-0.53, -0.45, 0.45, 0.53]) * width
    pts = np.stack([xs, np.zeros(4), np.zeros(4)], -1)
    vis = sun_visibility(half_plane(), pts, np.tile([0, 0, 1.0], (4, 1)), sun, 1024, np.random.default_rng(0))
    assert vis[0] == 0.0 and vis[3] == 1.0  # outside the predicted band: umbra and full sun
    assert 0.0 < vis[1] < 0.1 and 0.9 < vis[2] < 1.0  # just inside: a sliver of the disk


def test_limb_darkening_steepens_the_profile_like_a_numeric_reference():
    sun = SunSky(90.0, 40.0, 0.2665, limb_darkening=0.6)
    xs, vis, u, _, _ = edge_profile(sun, 1024)
    # Reference: integrate the limb-darkened disk below a chord at u (1D quadrature).
    y = np.linspace(-1, 1, 1601)
    x = np.linspace(-1, 1, 1601)
    yy, xx = np.meshgrid(y, x, indexing="ij")
    r2 = xx ** 2 + yy ** 2
    radiance = np.where(r2 <= 1, 1 - 0.6 * (1 - np.sqrt(np.clip(1 - r2, 0, 1))), 0.0)
    cum = np.cumsum(radiance.sum(1))
    cum /= cum[-1]
    ref = np.interp(np.clip(u, -1, 1), y, cum)
    assert np.max(np.abs(vis - ref)) < 0.03
    uniform = occluded_disk_visible(u)
    mid = np.abs(u) < 0.3
    # Limb darkening puts more light near the centre: a steeper middle than the uniform disk.
    slope_ld = np.polyfit(u[mid], vis[mid], 1)[0]
    slope_uni = np.polyfit(u[mid], uniform[mid], 1)[0]
    assert slope_ld > 1.05 * slope_uni


def test_edge_profile_converges_as_samples_grow():
    sun = SunSky(90.0, 40.0, 0.2665)
    errors = []
    for n in (16, 64, 256):
        _, vis, u, _, _ = edge_profile(sun, n, seed=3, n_points=401)
        errors.append(np.sqrt(np.mean((vis - occluded_disk_visible(u)) ** 2)))
    assert errors[1] < 0.6 * errors[0] and errors[2] < 0.6 * errors[1], errors


def test_sky_hidden_by_a_half_plane_matches_the_view_factor():
    xs = np.linspace(-3, 3, 13)
    pts = np.stack([xs, np.zeros_like(xs), np.zeros_like(xs)], -1)
    vis = sky_visibility(half_plane(), pts, np.tile([0, 0, 1.0], (13, 1)), 1024, seed=0)
    # Cosine-weighted sky left open beside an infinite edge at height H: (1 - (-x) / hypot(x, H)) / 2.
    ref = (1 - (-xs) / np.hypot(xs, H)) / 2
    assert np.max(np.abs(vis - ref)) < 0.012


def test_umbra_far_from_the_pillar_has_brightness_rho_up_to_hidden_sky():
    mesh = builtin_mesh("pillar")
    sun = SunSky.from_rho(180.0, 45.0, 0.2)
    # Points on the shadow's axis, 1.5-2.5 m from the base (the shadow is 3 m long, 0.2 m wide).
    d = np.linspace(1.5, 2.5, 9)
    pts = np.stack([np.zeros_like(d), -d * 0 + d, np.zeros_like(d)], -1)
    nrm = np.tile([0, 0, 1.0], (len(d), 1))
    sv = sun_visibility(mesh, pts, nrm, sun, 64, np.random.default_rng(0))
    assert np.all(sv == 0.0)
    sky = sky_visibility(mesh, pts, nrm, 4096, seed=0)
    ratio = (sun.sun_normal_irradiance * sun.direction[2] * sv + sun.sky_horizontal_irradiance * sky) / sun.lit_irradiance
    assert np.allclose(ratio, sun.rho * sky)
    # The pillar hides a little sky (0.4-4 %, the model's hidden-sky correction), never more.
    assert np.all(sky < 0.999) and np.all(sky > 0.96)
    assert np.all(np.abs(ratio / sun.rho - 1) < 0.04)


def test_shadow_reach_contains_every_point_that_loses_sun():
    mesh = builtin_mesh("dragon")
    sun = SunSky(120.0, 35.0, 0.5)
    rng = np.random.default_rng(4)
    pts = np.concatenate([rng.uniform(-4, 4, (3000, 2)), np.zeros((3000, 1))], 1)
    vis = sun_visibility(mesh, pts, np.tile([0, 0, 1.0], (len(pts), 1)), sun, 16, rng)
    reach = shadow_reach(mesh.vertices, sun, pts, margin_m=0.0, widen=1.0)
    assert np.all(reach[vis < 1.0])
    assert reach.mean() < 0.5  # and it is not everything


def test_sky_map_interpolates_the_direct_estimate():
    mesh = builtin_mesh("pillar")
    smap = sky_visibility_map(mesh, PlaneReceiver(), mesh.bounds, n_samples=1024, seed=0, fine_nodes=64)
    rng = np.random.default_rng(5)
    pts = np.concatenate([rng.uniform(-2.5, 2.5, (40, 2)), np.zeros((40, 1))], 1)
    pts = pts[np.max(np.abs(pts[:, :2]), 1) > 0.25]  # off the footprint
    direct = sky_visibility(mesh, pts, np.tile([0, 0, 1.0], (len(pts), 1)), 1024, seed=0)
    assert np.max(np.abs(smap.at(pts) - direct)) < 0.01


def test_bank_sky_visibility_sees_its_own_slope():
    bank = bank_terrain()
    smap = sky_visibility_map(bank.mesh, bank, np.array([[-0.1, -0.1, 0], [0.1, 0.1, 3.0]]), n_samples=256,
                              fine_nodes=24, coarse_margin_m=3.0, coarse_step_m=0.5)
    flat = smap.at(np.array([[0.0, -2.5]]))[0]
    foot = smap.at(np.array([[0.0, 1.2]]))[0]  # at the foot of the rise, looking up the slope
    assert flat > 0.97 and foot < flat - 0.02


def test_matches_independent_mitsuba_render_of_the_same_scene():
    import cv2
    from softshadow.camera import GroundGrid
    from data_synth.renderers import PhysicalRenderer, RenderQuality, SynthScene
    from data_synth.textures import GroundAppearance
    from data_synth.tracing import topdown_rays

    info = json.loads((MITSUBA / "render.json").read_text())
    img = cv2.imread(str(MITSUBA / info["image"]["png"]), cv2.IMREAD_UNCHANGED).astype(float)
    radiance = img / info["image"]["png_scale"]
    mesh = trimesh.load(MITSUBA / "occluder.obj", force="mesh", process=False)
    ratio = info["ratios"]["sky_over_sun_horizontal"]
    sun = SunSky.from_rho(info["sun"]["azimuth_deg"], info["sun"]["elevation_deg"], ratio / (1 + ratio),
                          info["sun"]["angular_radius_deg"])
    grid = GroundGrid(0.01, (-3.455, 4.105), 512, 512)  # as in the folder's scene.toml
    renderer = PhysicalRenderer(SynthScene(mesh, (0.5, 0.5, 0.5), PlaneReceiver()), RenderQuality(sun_samples=256))
    out = renderer.render(topdown_rays(grid), sun, GroundAppearance(np.full((4, 4, 3), 0.8, np.float32)),
                          np.random.default_rng(0))
    mine = out.irradiance / sun.lit_irradiance
    lit = info["expected_radiance"]["lit_ground"]
    ref = radiance / lit
    ground = out.kind == 1
    umbra = ground & (ref < 0.26)
    penumbra = ground & (ref > 0.3) & (ref < 0.95)
    assert umbra.sum() > 1000 and penumbra.sum() > 500
    assert abs(np.median(mine[ground]) - np.median(ref[ground])) < 0.01
    assert abs(mine[umbra].mean() / ref[umbra].mean() - 1) < 0.02
    assert np.mean(np.abs(mine[penumbra] - ref[penumbra])) < 0.03
    assert np.mean(np.abs(mine[ground] - ref[ground])) < 0.006


def test_adaptive_sun_sampling_agrees_with_full_sampling():
    from softshadow.camera import GroundGrid
    from data_synth.renderers import PhysicalRenderer, RenderQuality, SynthScene
    from data_synth.textures import GroundAppearance
    from data_synth.tracing import topdown_rays

    scene = SynthScene(builtin_mesh("pillar"), (0.5, 0.5, 0.5), PlaneReceiver())
    sun = SunSky.from_rho(200.0, 50.0, 0.3, 0.6)
    rays = topdown_rays(GroundGrid.around((0.6, 1.3), 3.0, 150))
    ground = GroundAppearance(np.full((4, 4, 3), 0.8, np.float32))
    maps = {}
    for adaptive in (False, True):
        q = RenderQuality(sun_samples=256, sky_samples=256, sky_fine_nodes=32, adaptive=adaptive)
        out = PhysicalRenderer(scene, q).render(rays, sun, ground, np.random.default_rng(1))
        maps[adaptive] = out.irradiance / sun.lit_irradiance
        if adaptive:
            assert 0 < out.stats["sun_refined_pixels"] < out.stats["sun_reach_pixels"]
    ok = np.isfinite(maps[True])
    penumbra = ok & (maps[False] > 0.35) & (maps[False] < 0.95)
    assert penumbra.sum() > 200
    assert abs(np.mean(maps[True][penumbra] - maps[False][penumbra])) < 0.005  # no bias
    assert np.max(np.abs(maps[True][ok] - maps[False][ok])) < 0.15  # noise only, no lost penumbra
