"""Levels of detail: the decimated series (softshadow.lod) and the fitter's automatic choice
(fitting.solve.lod) on a small mesh."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from softshadow import PAPER_FACE_COUNTS, decimate, lod_series


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
        assert lv.watertight == lv.mesh.is_watertight  # reported as it is, kept or not
        # The decimated mesh stays where the dragon is (quadric error keeps the surface; the
        # 300-face level loses the tips of the tail and claws, a few percent of the length).
        assert np.allclose(lv.mesh.bounds, dragon.bounds, atol=0.05 * np.ptp(dragon.vertices[:, 0]))
    assert levels[0].watertight


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
    from softshadow import Pose, SoftShadowModel, Sun
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
    result = {"faces": [41384, 5000, 300], "slides": [{"amplitude": 1.0, "frequency": 0.0},
                                                    {"amplitude": 1.0, "frequency": 15.0}],
              "ssim": [[1.0, 0.80, 0.40], [1.0, 0.97, 0.70]], "hidden_threshold": 0.95,
              "image_size": [40, 30], "render_seconds_per_image": [0.5, 0.2, 0.1], "date_utc": "today"}
    env = {"machine": {"cores": 2, "cpu": "cpu", "load_average_1_5_15_min": [1.0, 1.0, 1.0]}}
    text = masking_report(result, env, "img/lod_grid.png")
    assert "| 1, 15 | **0.970** | 0.700 |" in text and "| 1, 0 | 0.800 | 0.400 |" in text
    assert "- 5,000 faces: hidden by (1, 15)" in text
    assert "- 300 faces: hidden by no slide; the slide that hides it best is (1, 15), SSIM 0.700" in text


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
