"""Levels of detail: the decimated series (softshadow.lod) and the fitter's automatic choice
(fitting.solve.lod) on a small mesh."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from hypothesis import given, settings
from hypothesis import strategies as st

from softshadow import PAPER_FACE_COUNTS, GroundGrid, Pose, ShadowParams, SoftShadowModel, Sun, decimate, lod_series
from softshadow.lod import split_pinched


@pytest.fixture(scope="module")
def dragon():
    from benchmarks.meshes import mit_dragon
    return mit_dragon(full=True)


def test_series_follows_the_papers_counts_capped_at_the_mesh(dragon):
    levels = lod_series(dragon)
    assert len(dragon.faces) == 41384 and dragon.is_watertight
    # 69,000 is more than the mesh has: that level is the mesh itself, unchanged.
    assert levels[0].mesh is dragon and levels[0].faces == 41384 and levels[0].target == 41384
    assert [lv.target for lv in levels] == [41384, 5000, 1000, 300]
    for lv in levels[1:]:
        assert abs(lv.faces - lv.target) <= 10
        assert lv.watertight == lv.mesh.is_watertight  # reported as it is
        # The decimator pinches the 1,000- and 300-face levels at an edge; split, they stay closed.
        assert lv.watertight and SoftShadowModel.from_mesh(lv.mesh).occluder.watertight
        # The decimated mesh stays where the dragon is (quadric error keeps the surface; the
        # 300-face level loses the tips of the tail and claws, a few percent of the length).
        assert np.allclose(lv.mesh.bounds, dragon.bounds, atol=0.05 * np.ptp(dragon.vertices[:, 0]))
    assert levels[0].watertight


def _tetrahedron(a, b, c, d) -> np.ndarray:
    """The faces of the tetrahedron (a, b, c, d), wound consistently."""
    return np.array([[a, b, c], [a, d, b], [a, c, d], [b, d, c]])


def _pinched_pair(apex: np.ndarray) -> trimesh.Trimesh:
    """Two tetrahedra sharing the edge from (0, 0, 1) to (1, 0, 1) and nothing else: four faces
    on that edge. apex (4, 3): the other vertices, two above the edge's plane z = 1 (y > 0),
    two below (y < 0), so that the solids touch along the edge only."""
    vertices = np.vstack([[[0.0, 0.0, 1.0], [1.0, 0.0, 1.0]], apex])
    mesh = trimesh.Trimesh(vertices, np.vstack([_tetrahedron(0, 1, 2, 3), _tetrahedron(0, 1, 4, 5)]), process=False)
    trimesh.repair.fix_normals(mesh, multibody=True)  # each tetrahedron wound outward
    return mesh


def _pinched_apexes(draw_x, draw_h):
    return np.array([[draw_x[0], draw_h[0], 1.0 + draw_h[1]], [draw_x[1], draw_h[2], 1.0 - draw_h[3]],
                     [draw_x[2], -draw_h[4], 1.0 + draw_h[5]], [draw_x[3], -draw_h[6], 1.0 - draw_h[7]]])


@settings(max_examples=40, deadline=None)
@given(x=st.lists(st.floats(-0.5, 1.5), min_size=4, max_size=4),
       h=st.lists(st.floats(0.1, 1.0), min_size=8, max_size=8),
       order=st.randoms(use_true_random=False))
def test_split_pinched_closes_a_surface_pinched_at_an_edge(x, h, order):
    mesh = _pinched_pair(_pinched_apexes(x, h))
    # Any order of the faces and of each face's corners: the same closed surface.
    faces = np.asarray(mesh.faces)[order.sample(range(8), 8)]
    faces = np.array([np.roll(f, order.randrange(3)) for f in faces])
    mesh = trimesh.Trimesh(mesh.vertices, faces, process=False)
    uses = np.unique(np.sort(mesh.edges, axis=1), axis=0, return_counts=True)[1]
    assert not mesh.is_watertight and uses.max() == 4
    split = split_pinched(mesh)
    assert split.is_watertight and split.is_winding_consistent
    assert len(split.vertices) == len(mesh.vertices) + 2  # the shared edge's two vertices, once more
    assert np.array_equal(split.vertices[split.faces], mesh.vertices[mesh.faces])  # the triangles stay
    assert np.array_equal(split.vertices[:len(mesh.vertices)], mesh.vertices)  # the old indices too
    assert split.volume == pytest.approx(mesh.volume, rel=1e-12)
    assert SoftShadowModel.from_mesh(split).occluder.watertight


def test_split_pinched_leaves_open_and_unpinched_meshes():
    box = trimesh.creation.box()
    assert split_pinched(box) is box  # one fan per vertex
    open_box = trimesh.Trimesh(box.vertices, box.faces[1:], process=False)
    assert split_pinched(open_box) is open_box  # no split closes it
    # Two boxes touching at a corner (each edge has two faces): one vertex, two fans.
    a = trimesh.creation.box(bounds=[[0, 0, 0], [1, 1, 1]])
    b = trimesh.creation.box(bounds=[[1, 1, 1], [2, 2, 2]])
    corner = trimesh.util.concatenate([a, b])
    corner.merge_vertices()
    assert len(corner.vertices) == 15
    split = split_pinched(corner)
    assert len(split.vertices) == 16 and split.is_watertight
    assert np.array_equal(split.vertices[split.faces], corner.vertices[corner.faces])


def test_a_split_level_casts_the_pinched_surfaces_shadow():
    """The split mesh takes the closed path (lit faces only, silhouette where lit meets unlit)
    and casts the surface's shadow: at pixel centres as a ray caster finds it (as does the
    pinched mesh), and over each pixel's footprint as a 16 x 16 supersampled ray caster,
    also along the line where the two sheets meet (whose two coincident edges bound nothing)."""
    mesh = _pinched_pair(_pinched_apexes([0.2, 0.7, 0.4, 0.9], [0.6, 0.5, 0.3, 0.7, 0.5, 0.4, 0.8, 0.6]))
    split = split_pinched(mesh)
    assert SoftShadowModel.from_mesh(split).occluder.watertight
    assert not SoftShadowModel.from_mesh(mesh).occluder.watertight
    grid = GroundGrid(0.02, (-1.5, 2.5), 200, 200)
    rows, cols = np.mgrid[0:200, 0:200]
    n = 16
    sub = (np.arange(n) + 0.5) / n - 0.5
    for sun in (Sun(200.0, 40.0), Sun(120.0, 25.0), Sun(10.0, 70.0)):
        towards_sun = -np.asarray(sun.light_np, np.float64)

        def lit_fraction(r, c, offsets=((0.0, 0.0),)):
            o = np.asarray(offsets)
            x = grid.origin_m[0] + grid.pixel_m * (c[:, None] + o[None, :, 0])
            y = grid.origin_m[1] - grid.pixel_m * (r[:, None] + o[None, :, 1])
            points = np.stack([x, y, np.zeros_like(x)], -1).reshape(-1, 3)
            hit = mesh.ray.intersects_any(points, np.broadcast_to(towards_sun, points.shape))
            return 1.0 - hit.reshape(len(r), len(o)).mean(1)

        centres = lit_fraction(rows.ravel(), cols.ravel()).reshape(200, 200)
        assert 0.02 < 1.0 - centres.mean() < 0.5
        for m in (mesh, split):
            point = np.asarray(SoftShadowModel.from_mesh(m, footprint=False).ground_map(
                ShadowParams(0.0, 0.0), sun, Pose(), grid))  # the light left: 1 where lit
            assert np.array_equal(point, centres)
        area = np.asarray(SoftShadowModel.from_mesh(split).ground_map(ShadowParams(0.0, 0.0), sun, Pose(), grid))
        edge = np.argwhere((area > 0) & (area < 1) | (area != centres))
        offsets = np.stack(np.meshgrid(sub, sub), -1).reshape(-1, 2)
        truth = lit_fraction(edge[:, 0], edge[:, 1], offsets)
        assert len(edge) > 50 and np.abs(area[edge[:, 0], edge[:, 1]] - truth).max() < 1.5 / n


def test_series_drops_levels_the_mesh_cannot_fill():
    box = trimesh.creation.box()  # 12 faces: every level of the paper's series is the box itself
    levels = lod_series(box, PAPER_FACE_COUNTS)
    assert len(levels) == 1 and levels[0].mesh is box
    assert decimate(box, 300) is box
    with pytest.raises(ValueError, match="at least 4 faces"):
        decimate(box, 2)


def test_fitter_counts_halve_down_to_the_coarsest():
    from fitting.solve.lod import fitter_face_counts
    assert fitter_face_counts(5120) == [5120, 2560, 1280, 640, 300]
    assert fitter_face_counts(41384)[:3] == [41384, 20692, 10346] and fitter_face_counts(41384)[-1] == 300
    assert fitter_face_counts(500) == [500, 300]


def _ball() -> trimesh.Trimesh:
    ball = trimesh.creation.icosphere(subdivisions=4, radius=0.5)  # 5,120 faces
    ball.apply_translation([0.0, 0.0, 1.5])
    return ball


@pytest.fixture(scope="module")
def ball_folder(tmp_path_factory):
    from data_synth import model_topdown_folder
    return model_topdown_folder(tmp_path_factory.mktemp("lod") / "ball", k=0.02, rho=0.3, noise=0.004,
                                mesh=_ball())


def _fit(folder, **options):
    import fitting
    result = fitting.fit_folder(folder, options=fitting.FitOptions(plots=False, **options))
    (group,) = result.groups
    assert group.fitted, group.error
    return group


def test_automatic_choice_follows_the_tolerance(ball_folder):
    loose = _fit(ball_folder, lod="auto", lod_tolerance=1e9)
    assert loose.mesh_faces == 5120 and loose.lod_faces == 300  # anything goes: the coarsest
    strict = _fit(ball_folder, lod="auto", lod_tolerance=0.0)
    assert strict.lod_faces == 5120  # nothing may move: the full mesh
    off = _fit(ball_folder, lod="off")
    assert off.lod_faces == 5120
    # auto casts the hidden sky from a coarser level (2,560 faces) even when it keeps the full
    # mesh for the edges: that moves nothing that matters.
    assert abs(off.range_k - strict.range_k) < 0.05 * off.range_stderr
    assert abs(off.rho - strict.rho) < 0.05 * off.rho_stderr
    fixed = _fit(ball_folder, lod=1000)
    assert abs(fixed.lod_faces - 1000) <= 10
    # The coarsest level really changes the fit, so the strict choice kept the detail for a reason.
    # (Against the statistical error, the one lod's tolerance is measured in: the stated error adds
    # the systematic floor of fitting.solve.uncertainty.)
    assert abs(loose.range_k - off.range_k) > off.range_stderr_stat
    doc = off.to_json()
    assert doc["lod_faces"] == 5120 and doc["mesh_faces"] == 5120


def test_noise_lets_a_coarser_level_through(ball_folder, tmp_path):
    """The tolerance is in standard errors: a noisier photo (larger errors) hides more detail."""
    import jax

    from data_synth import model_topdown_folder
    from fitting.solve.lod import LevelsOfDetail, ShadowReference, choice_samples
    from softshadow import Pose, SoftShadowModel
    from fitting.photos.views import PhotoView
    import cv2

    ball = _ball()
    chosen = {}
    for noise in (0.004, 0.06):
        folder = model_topdown_folder(tmp_path / f"n{noise}", k=0.02, rho=0.3, noise=noise, mesh=ball)
        from scene import load_scene
        scene = load_scene(folder / "scene.toml")
        spec = scene.photo("top.png")
        gray = cv2.imread(str(folder / "top.png"), cv2.IMREAD_UNCHANGED).astype(np.float32) / 65535
        view = PhotoView("top.png", gray, np.zeros(gray.shape, bool),
                         grid=spec.camera.grid(gray.shape[1], gray.shape[0]),
                         sun_azimuth_deg=spec.sun_azimuth_deg, sun_elevation_deg=spec.sun_elevation_deg,
                         sun_source="given")
        with jax.enable_x64(True):
            full = SoftShadowModel.from_mesh(ball, profile="disk")
            lods = LevelsOfDetail(ball, full)
            samples, used = choice_samples(full, Pose(), [view], 0.03, 1300)
            reference = ShadowReference(full, Pose(), used, samples, 0.3, 0.03)
            chosen[noise] = lods.choose(reference, 1.0, "disk")
        assert 0.005 < reference.k_ref < 0.02  # one grid step below the k the photo shows (0.02)
        # The tolerance is in the errors the fit states: the systematic floor (8 % of k, 0.002 in
        # rho, known before the fit) in quadrature with the statistical part.
        np.testing.assert_allclose(reference.se_sys, [0.08 * reference.k_ref, 0.002])
        np.testing.assert_allclose(reference.se, np.hypot(reference.se_stat, reference.se_sys))
    quiet, noisy = chosen[0.004], chosen[0.06]
    assert noisy.faces < quiet.faces
    for choice in (quiet, noisy):
        assert all((c.worst <= 1.0) == (c.faces >= choice.faces) for c in choice.checks)


def test_levels_are_kept_per_mesh_between_fits():
    from fitting.solve.lod import levels_of_detail
    ball = _ball()
    lods = levels_of_detail(ball)
    faces, level = lods.level(1000)
    again = levels_of_detail(ball.copy())  # the same vertices and faces: the same levels
    assert again is lods and again.level(1000)[1] is level and abs(faces - 1000) <= 10
    assert levels_of_detail(ball, "paper") is not lods  # another rule, another model
    moved = ball.copy()
    moved.apply_translation([0.0, 0.0, 0.1])
    assert levels_of_detail(moved) is not lods


def test_stable_pick_keeps_the_same_pixels_when_the_band_moves():
    """Common random numbers: a band one row wider keeps almost every pixel the narrower band's
    draw kept, where a fresh random draw would keep about half of them."""
    from fitting.samples.photo_samples import stable_pick
    rows, cols = np.nonzero(np.ones((100, 200), bool))
    wide_rows, wide_cols = np.nonzero(np.ones((101, 200), bool))
    a = stable_pick(rows, cols, (120, 200), 5000, seed=3)
    b = stable_pick(wide_rows, wide_cols, (120, 200), 5000, seed=3)
    assert len(a) == len(b) == 5000 and np.all(np.diff(a) > 0)
    kept = set(zip(rows[a], cols[a]))
    shared = sum((r, c) in kept for r, c in zip(wide_rows[b], wide_cols[b]))
    assert shared >= 0.97 * 5000
    other = stable_pick(rows, cols, (120, 200), 5000, seed=4)
    assert len(np.intersect1d(a, other)) < 0.4 * 5000  # another seed, other pixels
    assert len(stable_pick(rows[:10], cols[:10], (120, 200), 5000, seed=3)) == 10  # fewer than asked: all


def test_cli_reports_the_level_in_results_and_table(ball_folder, tmp_path):
    import json

    from softshadow_cli.main import main
    out = tmp_path / "out"
    assert main(["fit", str(ball_folder), "--out", str(out), "--no-plots", "--lod", "640"]) == 0
    (group,) = json.loads((out / "results.json").read_text())["groups"]
    assert group["mesh_faces"] == 5120 and abs(group["lod_faces"] - 640) <= 10
    assert f"level of detail of {group['lod_faces']:,} of the mesh's 5,120 faces" in (out / "table2.md").read_text()


def test_masking_report_marks_the_levels_a_slide_hides():
    from benchmarks.lod_grid import masking_report
    table = {"faces": [41384, 5000, 300], "amplitudes": [0.5, 1.0], "frequencies": [0.0, 20.0], "ranges_k": [],
             "ssim": [[[[1.0, 0.8, 0.4]], [[1.0, 0.9, 0.6]]], [[[1.0, 0.8, 0.4]], [[1.0, 0.98, 0.7]]]],
             "margin": 0.01, "threshold": 0.95}
    choices = [{"amplitude": 1.0, "frequency": 0.0, "chosen_faces": 41384, "predicted_ssim": 1.0, "measured_ssim": 1.0,
                "measured_hidden": True, "coarsest_hidden_faces": 41384, "coarsest": True},
               {"amplitude": 1.0, "frequency": 15.0, "chosen_faces": 5000, "predicted_ssim": 0.97,
                "measured_ssim": 0.97, "measured_hidden": True, "coarsest_hidden_faces": 5000, "coarsest": True}]
    result = {"faces": [41384, 5000, 300], "slides": [{"amplitude": 1.0, "frequency": 0.0},
                                                    {"amplitude": 1.0, "frequency": 15.0}],
              "ssim": [[1.0, 0.80, 0.40], [1.0, 0.97, 0.70]], "hidden_threshold": 0.95,
              "image_size": [40, 30], "supersample": 2, "seconds_per_image": 0.2, "date_utc": "today",
              "table": table, "choices": choices, "check": {"slides": 2, "hidden": 2, "coarsest": 2}}
    env = {"machine": {"cores": 2, "cpu": "cpu", "load_average_1_5_15_min": [1.0, 1.0, 1.0]}}
    text = masking_report(result, env, "img/lod_grid.png")
    assert "| 1, 15 | **0.970** | 0.700 |" in text and "| 1, 0 | 0.800 | 0.400 |" in text
    assert "- 5,000 faces: hidden by (1, 15)" in text
    assert "- 300 faces: hidden by no slide; the slide that hides it best is (1, 15), SSIM 0.700" in text
    assert "| 1, 15 | 5,000 | 0.970 | 0.970 | 5,000 (chosen) |" in text
    assert "the chosen level is hidden (measured) under 2 and is the coarsest hidden level under 2" in text


def _masking_table(ssim, margin=0.0):
    from softshadow import MaskingTable
    ssim = np.asarray(ssim, float)
    return MaskingTable((1000, 500, 100), (0.5, 1.0), (0.0, 4.0, 16.0), (), ssim[:, :, None, :], margin)


def test_masking_table_interpolates_and_chooses_the_coarsest_hidden_level():
    """Grid values come back exactly; between them the prediction is linear in the amplitude and
    in log(1 + frequency); the choice is the coarsest level predicted above the threshold plus the
    margin, the full mesh when none is; the margin is the largest overestimate of a left-out value."""
    full = [1.0, 1.0, 1.0]
    ssim = [[[1.0, 0.80, 0.50], [1.0, 0.90, 0.70], [1.0, 0.94, 0.80]],
            [[1.0, 0.80, 0.50], [1.0, 0.96, 0.90], [1.0, 0.99, 0.96]]]
    table = _masking_table(ssim)
    np.testing.assert_allclose(table.predict(1.0, 4.0), [1.0, 0.96, 0.90])
    t = np.log1p(8.0) / np.log1p(16.0)  # 8 cycles on the log(1 + f) axis between 0 and 16
    mid = table.predict(0.75, 8.0)
    lo, hi = np.array(ssim[0]), np.array(ssim[1])
    at4 = lambda row: row[1] + (np.log1p(8.0) - np.log1p(4.0)) / (np.log1p(16.0) - np.log1p(4.0)) * (row[2] - row[1])
    np.testing.assert_allclose(mid, 0.5 * at4(lo) + 0.5 * at4(hi))
    assert 0 < t < 1 and np.allclose(table.predict(1.0, 99.0), ssim[1][2])  # held at the grid's end
    assert table.choose(1.0, 0.0) == 0  # the plain spotlight hides nothing
    assert table.choose(1.0, 4.0) == 1 and table.choose(1.0, 16.0) == 2
    assert _masking_table(ssim, margin=0.02).choose(1.0, 16.0) == 1  # the margin asks for more
    # Left out, 4 cycles at amplitude 1 is predicted from 0 and 16: 0.96 -> over by at most ...
    measured = _masking_table(ssim).with_margin()
    freq = (np.log1p(4.0) - 0.0) / np.log1p(16.0)
    guess = (1 - freq) * np.array(ssim[1][0]) + freq * np.array(ssim[1][2])
    assert measured.margin == pytest.approx(max(0.0, guess[1] - 0.96, guess[2] - 0.90))
    assert full == [1.0, 1.0, 1.0]
    from softshadow import MaskingTable
    again = MaskingTable.from_json(measured.to_json())
    assert again.faces == measured.faces and again.margin == pytest.approx(measured.margin, abs=1e-5)
    with pytest.raises(ValueError, match="finest first"):
        MaskingTable((100, 1000), (1.0,), (0.0,), (), np.ones((1, 1, 1, 2)))


def test_masking_table_of_a_small_scene_predicts_a_left_out_slide():
    """measure_masking_table on a tiny view of the ball and two coarser levels: the full mesh's
    SSIM is 1, the coarser levels' lower; a slide off the table's grid is predicted within the
    table's own interpolation error (its margin) plus a small allowance."""
    from softshadow import MaskingScene, SoftShadowModel, lod_series, masked_ssim, measure_masking_table
    from softshadow.internal import comparison_region, render_level_image
    mesh = trimesh.creation.icosphere(subdivisions=3, radius=0.5)  # 1,280 faces
    mesh.apply_translation([0.0, 0.0, 0.6])
    levels = [(lv.faces, SoftShadowModel.from_mesh(lv.mesh)) for lv in lod_series(mesh, (1280, 160, 60))]
    scene = MaskingScene(width=64, height=48, camera_position=(1.2, -2.0, 1.3), camera_target=(0.0, 0.0, 0.6),
                         projector_position=(-0.4, -1.9, 1.9), projector_target=(0.0, 0.0, 0.6), slide_px=96,
                         shadow_px=256)
    table = measure_masking_table(scene, levels, (0.5, 1.0), (0.0, 3.0, 8.0, 20.0), (0.005, 0.02), supersample=1)
    assert table.faces == tuple(f for f, _ in levels) and np.all(table.ssim[..., 0] == 1.0)
    assert np.all(table.ssim[..., 1:] < 1.0) and np.all(table.ssim[..., 2] <= table.ssim[..., 1] + 0.05)
    assert 0.0 <= table.margin < 0.2
    full, m0 = render_level_image(scene, levels[0][1], 0.75, 5.0, 0.01, 1)
    coarse, m2 = render_level_image(scene, levels[2][1], 0.75, 5.0, 0.01, 1)
    measured = masked_ssim(full, coarse, comparison_region(m0, m2))
    assert table.predict(0.75, 5.0, 0.01)[2] - measured <= table.margin + 0.05


def test_masking_choice_against_the_measured_grid():
    """The masking choice against the table ``softshadow bench --what lod-grid`` measured
    (docs/lod_masking.json): for each of the paper's slides the level the table predicts is hidden
    in the measured grid (SSIM >= the threshold), and is the coarsest hidden level in most cases.
    The table was measured on other slides than the paper's (only the spotlight is on both)."""
    import json
    from pathlib import Path

    from softshadow import MaskingTable
    path = Path(__file__).resolve().parents[1] / "docs" / "lod_masking.json"
    result = json.loads(path.read_text())["lod_grid"]
    table = MaskingTable.from_json(result["table"])
    assert table.faces == tuple(result["faces"])
    grid_points = {(a, f) for a in table.amplitudes for f in table.frequencies}
    coarsest = 0
    for slide, measured in zip(result["slides"], result["ssim"]):
        a, f = slide["amplitude"], slide["frequency"]
        assert f == 0 or (a, f) not in grid_points  # predicted, not looked up
        choice = table.choose(a, f)
        assert measured[choice] >= table.threshold, (slide, table.faces[choice], measured)
        hidden = [i for i, v in enumerate(measured) if v >= table.threshold]
        coarsest += choice == max(hidden)
    assert coarsest > len(result["slides"]) / 2


def test_bench_ceiling_is_the_fastest_levels_saving():
    """The LOD benchmark's ceiling: the fastest decimated level against the full mesh (off and
    auto never count), and the mesh's share of the full mesh's warm fit."""
    from benchmarks.lod import _ceiling
    rows = [{"lod": "off", "faces": 41384, "seconds": 2.0}, {"lod": "auto", "faces": 41384, "seconds": 0.5},
            {"lod": 20692, "faces": 20692, "seconds": 1.6}, {"lod": 1000, "faces": 1000, "seconds": 1.25},
            {"lod": 300, "faces": 300, "seconds": 1.3}]
    assert _ceiling(rows) == {"faces": 1000, "speedup_warm": 1.6, "mesh_share_warm": 0.375}


def test_bench_shifts_are_in_the_full_meshs_errors():
    """The LOD benchmark's shifts: a level's k and rho minus the full mesh's, over the full mesh's
    stated and statistical errors, and its warm speed-up."""
    from benchmarks.lod import _shifts
    full = {"error": None, "range_k": 0.010, "rho": 0.25, "range_stderr": 0.001, "rho_stderr": 0.002,
            "range_stderr_stat": 0.0005, "rho_stderr_stat": 0.001, "seconds": 2.0}
    row = dict(full, range_k=0.0095, rho=0.254, seconds=0.5)
    _shifts(row, full)
    assert row["k_shift_se"] == pytest.approx(-0.5) and row["rho_shift_se"] == pytest.approx(2.0)
    assert row["k_shift_se_stat"] == pytest.approx(-1.0) and row["rho_shift_se_stat"] == pytest.approx(4.0)
    assert row["speedup_warm"] == pytest.approx(4.0)


def test_auto_hands_its_samples_to_the_fit_when_it_keeps_the_full_mesh(ball_folder, monkeypatch):
    """The choice draws the fit's own samples; when it keeps the full mesh the fit uses them
    instead of drawing them again (one draw per group, as with --lod off)."""
    import fitting.solve.group as group
    calls = []
    draw = group.sample_views

    def counted(*args, **kwargs):
        calls.append(args[0])
        return draw(*args, **kwargs)

    monkeypatch.setattr(group, "sample_views", counted)
    strict = _fit(ball_folder, lod="auto", lod_tolerance=0.0)
    assert strict.lod_faces == 5120 and len(calls) == 1
    calls.clear()
    _fit(ball_folder, lod="off")
    assert len(calls) == 1
    calls.clear()
    loose = _fit(ball_folder, lod="auto", lod_tolerance=1e9)  # a level chosen: the fit draws on it
    assert loose.lod_faces == 300 and len(calls) == 2 and len(calls[1].occluder.faces) == 300


def test_levels_are_kept_on_disk(tmp_path, monkeypatch):
    """A level decimated once is read back by the next process (here: after the in-memory levels
    are gone), not decimated again."""
    import fitting.solve.lod as lod
    monkeypatch.setenv("SOFTSHADOW_JAX_CACHE", str(tmp_path / "cache"))
    ball = _ball()
    first = lod.level_store(ball, 1000)
    assert list((tmp_path / "cache" / "levels").glob("*.npz"))

    def no_decimation(*args, **kwargs):
        raise AssertionError("decimated again")

    monkeypatch.setattr(lod, "decimate", no_decimation)
    again = lod.level_store(ball, 1000)
    np.testing.assert_array_equal(again.faces, first.faces)
    np.testing.assert_allclose(again.vertices, first.vertices)
    assert lod.level_store(ball, 10_000) is ball  # no fewer faces: the mesh itself
    monkeypatch.setenv("SOFTSHADOW_JAX_CACHE", "off")
    monkeypatch.setattr(lod, "decimate", lambda mesh, faces: first)
    assert lod.level_store(ball, 999) is first  # no store: decimated
