"""The speed-against-error harness: it runs on tiny sizes and writes its keys and files.

Timings are not checked (the machine is shared); the error arithmetic is, on cases with a
known answer.
"""

from __future__ import annotations

import dataclasses
import json

import jax
import numpy as np
import pytest

from softshadow import GroundGrid
from benchmarks.meshes import bench_mesh, decimated, mit_dragon
from benchmarks.reference import PhysicalReference, block_mean
from benchmarks.speed_report import pareto_front
from benchmarks.scenes import image_error, linear_equivalent_k
from benchmarks.scaling import loglog_slope
from benchmarks.table1 import crossing_width


def test_pareto_front_keeps_only_undominated_points():
    pts = [(10.0, 0.5), (1.0, 1.0), (5.0, 0.2), (20.0, 0.3), (2.0, 1.5)]
    assert pareto_front(pts) == [1, 2]


def test_block_mean_of_a_nested_grid_is_the_coarse_pixel():
    fine = GroundGrid.around((0.3, -0.2), 2.0, 8)
    coarse = GroundGrid.around((0.3, -0.2), 2.0, 4)
    x = fine.pixel_centres()[..., 0]
    np.testing.assert_allclose(block_mean(x, 2), coarse.pixel_centres()[..., 0], atol=1e-12)


def test_image_error_is_zero_for_the_truth_and_sees_a_band_offset():
    grid = GroundGrid.around((0.0, 0.0), 1.0, 8)
    shading = np.linspace(0.2, 1.0, 64).reshape(8, 8)
    vis = np.zeros((8, 8))
    vis[2:4] = 0.5  # two rows of penumbra
    ref = PhysicalReference(shading, vis, 0.0, 0.0)
    none = lambda g: np.zeros((g.height, g.width), bool)
    assert image_error(shading, grid, ref, grid, none)["rms"] == 0.0
    off = shading.copy()
    off[2:4] += 0.1
    e = image_error(off, grid, ref, grid, none)
    assert e["rms_band"] == pytest.approx(0.1) and e["rms"] == pytest.approx(0.1 * np.sqrt(16 / 64))
    # A render twice as fine, block-averaged, compares equal.
    fine = np.kron(shading, np.ones((2, 2)))
    assert image_error(fine, GroundGrid.around((0.0, 0.0), 1.0, 16), ref, grid, none)["rms"] < 1e-12


def test_crossing_width_interpolates_both_ends():
    # Below 0.5 from x = 1.5 to x = 4.5 (samples 1 m apart): 3 m.
    p = np.array([1.0, 0.75, 0.25, 0.0, 0.25, 0.75, 1.0])
    assert crossing_width(p, 0.5, 1.0) == pytest.approx(3.0)
    # From 1 + 0.1 / 0.6 to 4 + 0.3 / 0.8 samples, 2 m apart.
    assert crossing_width(np.array([1.0, 0.6, 0.0, 0.0, 0.2, 1.0]), 0.5, 2.0) == pytest.approx(2.0 * (4.375 - 1 - 1 / 6))
    assert crossing_width(np.ones(5), 0.5, 1.0) == 0.0


def test_loglog_slope():
    x = np.array([10.0, 100.0, 1000.0])
    assert loglog_slope(x, 3 * x ** 1.5) == pytest.approx(1.5)
    assert loglog_slope([1.0], [2.0]) is None


def test_naive_renderer_matches_the_renderer_on_the_pillar():
    from softshadow import Pose, ShadowParams, SoftShadowModel, Sun
    from benchmarks.naive import NaiveRenderer
    from benchmarks.scenes import scene_grid
    mesh = bench_mesh("pillar")
    s = -np.asarray(Sun(200.0, 40.0).light_np)
    grid = scene_grid(mesh, s, 48)
    naive = NaiveRenderer(mesh).render(s, grid, 0.02, 0.2)
    # The naive renderer samples pixel centres and models no hidden sky: so does this model.
    model = SoftShadowModel.from_mesh(mesh, footprint=False, hidden_sky=False)
    ours = np.asarray(model.ground_map(ShadowParams(0.02, 0.2), Sun(200.0, 40.0), Pose(), grid))
    assert np.sqrt(np.mean((naive - ours) ** 2)) < 0.01 and np.mean(np.abs(naive - ours) > 0.05) < 0.01


def test_linear_ramp_closest_to_the_disk_profile():
    # docs/formats.md: the best-fitting linear ramp to a real disk is about 0.854 tan r.
    assert linear_equivalent_k(0.01) == pytest.approx(0.00854, abs=3e-5)


def test_vendored_dragon_has_the_papers_face_count_and_stands_on_the_ground():
    m = mit_dragon()
    assert len(m.faces) == 26584 and m.is_watertight
    assert m.bounds[0, 2] == pytest.approx(0.0) and np.ptp(m.vertices[:, 0]) == pytest.approx(1.6)
    assert bench_mesh("dragon") is m
    assert abs(len(decimated(m, 1000).faces) - 1000) <= 10


def test_sweep_tiny_writes_json_report_and_plot(tmp_path, monkeypatch, capsys):
    """The whole sweep at its tiny size (the full one is behind ``softshadow bench --what sweep``),
    Mitsuba reported as skipped, the report made from the run's JSON."""
    from benchmarks import mitsuba_peer, sweep_and_report
    from benchmarks.scenes import SweepSettings
    monkeypatch.setenv("SOFTSHADOW_BENCH_CACHE", str(tmp_path / "cache"))
    monkeypatch.setattr(mitsuba_peer, "mitsuba_available", lambda: False)
    out, md = tmp_path / "bench.json", tmp_path / "docs" / "speed.md"
    with jax.enable_x64(False):  # the command line's precision (and its compiled programs, shared)
        sweep_and_report(SweepSettings.tiny(), fit=False, json_path=out, report_path=md)
    assert "skipped: mitsuba not installed" in capsys.readouterr().err
    result = json.loads(out.read_text())
    assert result["mitsuba"] == {"skipped": "mitsuba not installed"}
    for key in ("pillar", "ball", "dragon"):
        case = result[key]
        assert case["median_ms"] > 0 and case["error"]["rms"] >= 0 and case["error"]["band_pixels"] > 0
        assert case["mesh"] == key
    for sweep in ("resolution", "profile", "dtype"):  # tiny: one value each, no level of detail
        assert result[sweep] and all("error" in c for c in result[sweep])
    assert [c["dtype"] for c in result["dtype"]] == ["float32"] and result["lod"] == []
    for key in ("pillar", "ball", "dragon"):  # the paper's algorithm, hard and soft, beside Table 3
        row = result["paper"]["table3"][key]
        assert row["paper_soft_ms"] > row["paper_hard_ms"] and "error" in row["soft"] and "error" in row["hard"]
    assert [r["label"] for r in result["paper"]["table2"]] == ["09:20", "13:21", "16:21"]
    assert [r["distance_m"] for r in result["table1"]] == [0.3, 1.5, 3.0]
    sc = result["scaling"]
    assert [r["faces"] for r in sc["by_faces"]] == [176, 1472] and "median_ms" in sc["by_faces"][0]["naive"]
    assert set(sc["slope_vs_faces"]) == {"softshadow", "paper", "naive"}
    law = sc["cost_model"]  # four timed cases: both laws fitted, residuals reported
    assert law["points"] == 4 and law["pixels_plus_edges"]["rms_rel_residual"] >= 0
    assert "fit_samples" not in result and "fit_baseline" not in result  # fit=False

    def timed_renderers(node):
        if isinstance(node, dict):
            if "renderer" in node and "median_ms" in node:
                yield node
            for v in node.values():
                yield from timed_renderers(v)
        elif isinstance(node, list):
            for v in node:
                yield from timed_renderers(v)

    timed = list(timed_renderers(result))
    assert len(timed) >= 12 and all("rms" in c["error"] for c in timed)  # every timed renderer has its error
    env = result["environment"]
    assert env["versions"]["jax"] and len(env["machine"]["load_average_1_5_15_min"]) == 3
    assert len(env["load_average_at_end"]) == 3
    assert list((tmp_path / "cache").glob("reference-*.npz"))  # the truth is cached
    text = md.read_text()
    assert "img/speed_vs_error_pareto.png" in text and env["date_utc"] in text
    assert "Table 1" in text and "Table 3" in text and "Table 2 in the paper's own parameters" in text
    assert "Skipped: mitsuba not installed" in text and "Cost grows with pixels plus silhouette edges?" in text
    for mesh in ("pillar", "ball", "dragon"):
        assert f"| {mesh} |" in text.split("Pareto front of each mesh")[1].split("## The meshes")[0]
    assert (md.parent / "img" / "speed_vs_error_pareto.png").stat().st_size > 1000
    assert (md.parent / "img" / "speed_vs_error_scaling.png").stat().st_size > 1000


def test_cost_model_tells_a_sum_from_a_product():
    from benchmarks.scaling import cost_model
    rows = [{"pixels": p, "silhouette_edges": e, "softshadow": {"median_ms": 1.0 + 2e-5 * p + 3e-3 * e}}
            for p in (1e4, 4e4, 1.6e5) for e in (50, 500, 5000)]
    law = cost_model(rows)
    a = law["pixels_plus_edges"]
    assert a["rms_rel_residual"] < 1e-6 and a["ms_per_megapixel"] == pytest.approx(20.0, rel=1e-4)
    assert a["ms_per_thousand_edges"] == pytest.approx(3.0, rel=1e-4)
    assert law["pixels_times_edges"]["rms_rel_residual"] > 0.1


def test_time_mitsuba_needs_is_interpolated_or_extrapolated():
    from benchmarks.mitsuba_peer import time_to_reach
    t, e = [10.0, 40.0, 160.0], [0.04, 0.02, 0.01]
    assert time_to_reach(t, e, 0.02) == {"ms": pytest.approx(40.0), "how": "interpolated"}
    assert time_to_reach(t, e, 0.0283)["ms"] == pytest.approx(20.0, rel=0.01)
    far = time_to_reach(t, e, 0.005)
    assert far["ms"] == pytest.approx(640.0) and far["how"].startswith("extrapolated")
    assert time_to_reach(t, e, 0.05)["how"] == "at the fewest samples measured"
    # Above a floor of 0.006 only the noise part falls: (0.01^2 - 0.006^2) / (0.008^2 - 0.006^2) x 160 ms.
    hit = time_to_reach(t, e, 0.008, floor=0.006)
    assert hit["ms"] == pytest.approx(160.0 * (1e-4 - 3.6e-5) / (6.4e-5 - 3.6e-5)) and "floor" in hit["how"]
    below = time_to_reach(t, e, 0.005, floor=0.006)
    assert below["ms"] is None and below["how"].startswith("not reached") and below["at_least_ms"] == 160.0
    assert time_to_reach(t, e, 0.02, floor=0.006)["how"] == "interpolated"  # measured points need no model


def test_mitsuba_report_states_a_floor_and_a_lower_bound():
    from benchmarks.speed_report import _mitsuba_section
    case = {"spp": 64, "pixels": 32, "median_ms": 100.0, "noise_rms_band": 0.003, "floor_rms_band": 0.005,
            "error": {"rms": 0.001, "rms_band": 0.0058, "max_abs": 0.1}}
    reach = {"rms_band": {"target": 0.004, "softshadow_ms": 2.0, "mitsuba_ms": None, "ratio": None,
                          "ratio_at_least": 50.0, "how": "not reached: below Mitsuba's floor 0.0050 against this truth"},
             "noise_band": {"target": 0.004, "softshadow_ms": 2.0, "mitsuba_ms": 200.0, "ratio": 100.0,
                            "how": "interpolated"}}
    run = {"variant": "llvm_ad_rgb", "setup_label": "disk sun", "reference_noise_rms_band": 0.003,
           "cases": [case], "time_to_reach": {"softshadow (wedge)": reach}}
    text = "\n".join(_mitsuba_section({"dragon": run}))
    assert "| dragon | softshadow (wedge) | penumbra band | 0.0040 | 2.0 | not reached |" in text and "| > 50 |" in text
    assert "penumbra band, Mitsuba's noise only | 0.0040 | 2.0 | 200 | interpolated | 100 |" in text
    assert "differ by 0.0040 (RMS, band)" in text  # sqrt(0.005^2 - 0.003^2)


def test_a_probe_that_aborts_its_process_reads_false_in_a_child():
    """Mitsuba's LLVM variant aborts the process that renders where the system's libLLVM is too
    old (no exception reaches Python): the bench probes it in a child process and goes on."""
    from benchmarks.mitsuba_peer import _runs_in_child
    assert _runs_in_child("pass")
    assert not _runs_in_child("import os; os.abort()")
    assert not _runs_in_child("raise SystemExit(3)")
    assert not _runs_in_child("import time; time.sleep(30)", timeout_s=0.5)


def test_mitsuba_setup_checks_its_options_and_names_itself():
    from benchmarks.mitsuba_peer import EFFICIENT, PLAIN, MitsubaSetup
    with pytest.raises(ValueError, match="sun_share must be in"):
        MitsubaSetup(sun_share=1.0)
    with pytest.raises(ValueError, match="disk sun only"):
        MitsubaSetup(sun="envmap", sun_share=0.5)
    assert PLAIN.label == "disk sun, ldsampler"
    assert EFFICIENT.label == "disk sun, multijitter, sun share 0.8, 4 light + 1 BSDF samples"


def test_envmap_sun_holds_the_disks_irradiance_and_points_at_the_sun():
    """The environment map's sun (whole rows around the map's pole, bilinear between rows) has the
    irradiance of a uniform disk of the sun's radius, and its pole is turned onto the sun."""
    import math
    from data_synth import SunSky
    from benchmarks.mitsuba_peer import _envmap_rows, _envmap_sun_integral, _sun_sky_envmap
    r = math.radians(0.2665)
    h, weight = _envmap_rows(r)
    assert weight[:17].all() and not weight[17:].any()
    edge = 16.5 * math.pi / (h - 1)  # half-way between the last lit row and the first dark one
    assert edge == pytest.approx(r, rel=2e-3)
    disk = math.pi * math.sin(r) ** 2  # integral of cos over a cone of half-angle r
    assert _envmap_sun_integral(r) == pytest.approx(disk, rel=1e-3)
    light = SunSky.from_rho(200.0, 40.0, 0.2)
    img, to_world = _sun_sky_envmap(light)
    assert img.shape[0] == h and img.shape[2] == 3
    np.testing.assert_allclose(img[-1], light.sky_radiance, rtol=1e-6)  # the sky alone away from the sun
    np.testing.assert_allclose(to_world[:3, 1], light.direction, atol=1e-12)  # local +y, the pole
    np.testing.assert_allclose(to_world[:3, :3].T @ to_world[:3, :3], np.eye(3), atol=1e-12)
    assert np.linalg.det(to_world[:3, :3]) == pytest.approx(1.0)


@pytest.mark.parametrize("setup_kw", [dict(sun="envmap", sampler="multijitter"),
                                      dict(sampler="multijitter", sun_share=0.8, emitter_samples=4),
                                      dict(sampler="independent", mono=True)])
def test_mitsuba_setups_light_open_ground_alike(setup_kw):
    """Where Mitsuba is installed: every set-up's scene loads and lights open ground at the
    renderer's unit shading (1), away from the object."""
    pytest.importorskip("mitsuba")
    import trimesh
    from data_synth import SunSky
    from softshadow import GroundGrid
    from benchmarks.mitsuba_peer import MitsubaScene, MitsubaSetup, mitsuba_variant
    setup = MitsubaSetup(**setup_kw)
    far_box = trimesh.creation.box(extents=(0.05, 0.05, 0.05))
    far_box.apply_translation((50.0, 50.0, 0.025))
    ms = MitsubaScene(far_box, SunSky.from_rho(200.0, 40.0, 0.2), GroundGrid.around((0.0, 0.0), 1.0, 16), setup)
    assert mitsuba_variant(mono=setup.mono) in ("llvm_ad_mono", "llvm_ad_rgb", "scalar_rgb")
    img = ms.render(64)
    assert img.shape == (16, 16) and abs(img.mean() - 1.0) < 0.02


def test_mitsuba_peer_renders_the_bench_scene(tmp_path, monkeypatch):
    """Where Mitsuba is installed (the optional extra), its top-down render of the pillar agrees
    with the physical truth (the same scene) and its cases carry errors."""
    pytest.importorskip("mitsuba")
    from benchmarks.meshes import bench_mesh
    from benchmarks.mitsuba_peer import bench_mitsuba
    from benchmarks.scenes import BenchScene, SweepSettings
    monkeypatch.setenv("SOFTSHADOW_BENCH_CACHE", str(tmp_path / "cache"))
    s = SweepSettings.tiny()
    s.reference_pixels, s.reference_samples = 48, 64
    scene = BenchScene(bench_mesh("pillar"), s, name="pillar")
    run = bench_mitsuba(scene, (16, 64), targets={"x": {"median_ms": 1.0, "error": {"rms": 0.01, "rms_band": 0.05}}})
    errs = [c["error"]["rms"] for c in run["cases"]]
    assert run["variant"] in ("llvm_ad_rgb", "scalar_rgb") and [c["spp"] for c in run["cases"]] == [16, 64]
    # The same scene: a mirrored or misplaced shadow would read tenths, not hundredths.
    assert errs[1] < 0.03 and run["time_to_reach"]["x"]["rms"]["mitsuba_ms"] > 0
    for c in run["cases"]:  # two independent renders: noise, and the error that is not noise
        assert 0 < c["noise_rms_band"] and c["floor_rms_band"] ** 2 <= c["error"]["rms_band"] ** 2 + 1e-15
    assert run["setup_label"] == "disk sun, multijitter, sun share 0.8, 4 light + 1 BSDF samples"


def test_mitsuba_setups_compared_round_robin(tmp_path, monkeypatch):
    pytest.importorskip("mitsuba")
    from benchmarks.meshes import bench_mesh
    from benchmarks.mitsuba_peer import EFFICIENT, PLAIN, compare_setups
    from benchmarks.scenes import BenchScene, SweepSettings
    monkeypatch.setenv("SOFTSHADOW_BENCH_CACHE", str(tmp_path / "cache"))
    s = SweepSettings.tiny()
    s.reference_pixels, s.reference_samples = 32, 64
    scene = BenchScene(bench_mesh("pillar"), s, name="pillar")
    rows = compare_setups(scene, {"plain": PLAIN, "efficient": EFFICIENT}, 16, repeats=1)
    assert [r["name"] for r in rows] == ["plain", "efficient"] and rows[0]["efficiency"] == pytest.approx(1.0)
    assert all(r["median_ms"] > 0 and r["noise_rms_band"] > 0 and r["error"]["rms"] < 0.1 for r in rows)


def test_truth_traces_the_sky_next_to_walls_where_the_sky_map_is_coarse():
    """Beside the pillar the sky map's bilinear cells mix nodes inside the post with nodes outside:
    there the truth traces each point (as Mitsuba does), elsewhere it keeps the map."""
    from data_synth import PlaneReceiver, sky_visibility, sky_visibility_map
    from benchmarks.reference import ground_sky
    mesh = bench_mesh("pillar")  # 0.2 x 0.2 m, centred on the origin
    n = 64
    pts = np.array([[0.11, 0.0, 0.0], [0.0, -0.12, 0.0], [1.9, 1.5, 0.0], [-2.5, 0.4, 0.0]])
    up = np.tile([0.0, 0.0, 1.0], (len(pts), 1))
    traced = sky_visibility(mesh, pts, up, n)
    smap = sky_visibility_map(mesh, PlaneReceiver(), mesh.bounds, n_samples=n)
    mapped = dataclasses.replace(smap, mesh=None).at(pts[:, :2])  # interpolation alone
    got = ground_sky(mesh, pts, n)
    assert np.all(traced[:2] - mapped[:2] > 0.1)  # the map reads far too dark at the wall
    np.testing.assert_allclose(got[:2], traced[:2], atol=1e-12)
    np.testing.assert_allclose(got[2:], mapped[2:], atol=1e-12)
    assert np.all(np.abs(traced[2:] - mapped[2:]) < 0.01)
