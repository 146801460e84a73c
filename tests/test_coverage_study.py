"""The calibration study's machinery at a small size: draws, misdescribed folders, tables, report, one fit.

The full study is a benchmark (``softshadow bench --what coverage``); here a fixed draw of
tiny groups checks that a draw is reproducible from its seed and its JSON, that every factor
of the study is exercised, that misdescribed folders say what the draw says they get wrong,
that the tables are computed right from hand-made records, and that a well-described small
group is fitted and covered.
"""

from __future__ import annotations

import datetime as dt
import functools
import json
import math

import numpy as np
import pytest

from benchmarks.coverage import group_draw, parse_indices, study_meshes, study_prior
from benchmarks.coverage_tables import FACTORS, bin_table, criteria, factor_bin, judge, summarize
from data_synth.draw import SceneDraw, ScenePrior, draw_parameters, synthesize_draw
from data_synth.misdescription import Misdescription
from data_synth.receivers import rising_bank
from data_synth.renderers import RenderQuality
from data_synth.sun_site import site_and_time_for_sun
from scene import load_scene, solar_position

FAST = RenderQuality(sun_samples=16, sky_samples=256, sky_fine_nodes=48, object_sky_samples=16)
TINY = dict(pixels=(320 * 240, 400 * 300), photos=(1, 2), meshes=("pillar", "ball"))


@pytest.fixture(scope="module")
def meshes():
    return study_meshes()


def test_draw_is_reproducible_from_seed_and_json(meshes):
    a = group_draw(7, 3, meshes=meshes)
    b = group_draw(7, 3, meshes=meshes)
    assert a == b
    assert group_draw(7, 4, meshes=meshes) != a
    again = SceneDraw.from_json(json.loads(json.dumps(a.to_json())))
    assert again == a


def test_every_factor_of_the_study_is_exercised(meshes):
    prior = study_prior()
    draws = [draw_parameters(np.random.default_rng([11, i]), prior, meshes).to_json() for i in range(160)]
    for factor, (_, bins) in FACTORS.items():
        seen = {factor_bin(d, factor) for d in draws}
        assert seen == set(bins), (factor, set(bins) - seen)
    assert any(d["receiver_fallback"] for d in draws)  # a receiver the shadow cannot reach: the ground
    assert {d["fmt"] for d in draws} == {"jpg", "png"}
    for d in draws:
        assert 8.0 - 0.1 <= d["sun_elevation_deg"] <= 85.0 + 0.1
        assert 0.002 <= d["range_k"] <= 0.03 and 0.03 <= d["rho"] <= 0.9
        assert 1 <= len(d["photo_draws"]) <= 6 and 320 <= d["width"] <= 4000
        assert d["width"] * d["height"] * len(d["photo_draws"]) <= prior.group_pixel_budget or \
            len(d["photo_draws"]) == 1
        if d["misdescription"] == "sun":
            assert d["sun_source"] == "given" and 0.5 <= math.hypot(
                d["sun_offset_deg"][0] * math.cos(math.radians(d["sun_elevation_deg"])), d["sun_offset_deg"][1]) <= 3.0
        if d["misdescription"] == "clock":
            assert d["sun_source"] == "time+site" and 300 <= abs(d["clock_offset_s"]) <= 1200
        if d["misdescription"] == "scale":
            assert 0.02 <= abs(d["scale_factor"] - 1) <= 0.15
        if d["misdescription"] == "position":
            assert 0.01 <= math.hypot(*d["position_offset_m"][:2]) <= 0.05
        if d["misdescription"] == "lod":
            assert d["fit_lod"] >= 60


@pytest.mark.parametrize("target", [(90.0, 8.0), (200.0, 85.0), (330.0, 30.0), (12.0, 55.0)])
def test_site_and_time_give_the_drawn_sun(target):
    site, when, got = site_and_time_for_sun(*target, np.random.default_rng(1))
    assert when.tzinfo is not None
    az, el = solar_position(when, site["latitude"], site["longitude"])
    assert (az, el) == pytest.approx(got)
    assert abs((az - target[0] + 180) % 360 - 180) * math.cos(math.radians(el)) < 0.1
    assert el == pytest.approx(target[1], abs=0.1)


def test_rising_bank_gradient_matches_its_heights():
    bank = rising_bank(37.0, start_m=0.8, rise_m=0.4, width_m=1.5, bump_m=0.02)
    rng = np.random.default_rng(0)
    x, y = rng.uniform(-3, 3, 200), rng.uniform(-3, 3, 200)
    fx, fy = bank.grad(x, y)
    h = 1e-6
    assert fx == pytest.approx((bank.f(x + h, y) - bank.f(x - h, y)) / (2 * h), abs=1e-6)
    assert fy == pytest.approx((bank.f(x, y + h) - bank.f(x, y - h)) / (2 * h), abs=1e-6)
    a = math.radians(37.0)
    far = np.array([[math.sin(a) * 5.0, math.cos(a) * 5.0]])
    assert bank.height(far)[0] == pytest.approx(0.4, abs=0.03)  # risen, bumps damped to a fifth
    assert bank.max_slope() < 1.5 * 0.4 / 1.5 + 3.5 * 0.02


def test_group_truth_averages_azimuths_around_north():
    from data_synth.synth import _mean_azimuth
    assert _mean_azimuth([359.0, 1.0, 3.0]) == pytest.approx(1.0)
    assert _mean_azimuth([350.0, 350.0]) == pytest.approx(350.0)


def test_misdescription_changes_what_is_written():
    told = Misdescription(scale_factor=1.1, position_offset_m=(0.03, 0.0, 0.0), sun_offset_deg=(1.0, -0.5),
                          clock_offset_s=600)
    assert told.kinds == ("scale", "position", "sun", "clock")
    assert Misdescription().kinds == ()
    assert told.scale(2.0) == pytest.approx(2.2)
    assert told.sun(359.5, 40.0) == pytest.approx((0.5, 39.5))
    t = dt.datetime(2026, 4, 20, 10, 0, tzinfo=dt.UTC)
    assert told.time(t) - t == dt.timedelta(minutes=10)
    with pytest.raises(ValueError):
        Misdescription(scale_factor=0.0)


def _tiny(seed, **over):
    return draw_parameters(np.random.default_rng([seed, 0]), ScenePrior(**{**TINY, **over}))


def test_misdescribed_folders_say_what_the_draw_gets_wrong(tmp_path):
    import piexif
    scale = _tiny(1, well_described_share=0.0, misdescription_weights={"scale": 1.0}, receivers={"plane": 1.0})
    folder = synthesize_draw(scale, tmp_path / "scale", render_quality=FAST)
    spec = load_scene(folder / "scene.toml")
    truth = json.loads((folder / "truth.json").read_text())
    assert spec.object.scale == pytest.approx(scale.object_scale * scale.scale_factor)
    assert truth["object"]["scale"] == pytest.approx(scale.object_scale)
    assert truth["misdescription"]["kinds"] == ["scale"] and SceneDraw.from_json(truth["draw"]) == scale

    clock = _tiny(2, well_described_share=0.0, misdescription_weights={"clock": 1.0},
                  sun_sources={"time+site": 1.0}, receivers={"plane": 1.0}, png_share=0.0)
    folder = synthesize_draw(clock, tmp_path / "clock", render_quality=FAST)
    truth = json.loads((folder / "truth.json").read_text())
    photo = truth["groups"][0]["photos"][0]
    exif = piexif.load(str(folder / photo))["Exif"][piexif.ExifIFD.DateTimeOriginal].decode()
    true_time = dt.datetime.fromisoformat(truth["photos_detail"][photo]["time"])
    written = dt.datetime.strptime(exif, "%Y:%m:%d %H:%M:%S").replace(tzinfo=true_time.tzinfo)
    assert (written - true_time).total_seconds() == pytest.approx(clock.clock_offset_s, abs=1)
    assert load_scene(folder / "scene.toml").site is not None

    sun = _tiny(3, well_described_share=0.0, misdescription_weights={"sun": 1.0}, sun_sources={"given": 1.0},
                receivers={"plane": 1.0})
    folder = synthesize_draw(sun, tmp_path / "sun", render_quality=FAST)
    spec = load_scene(folder / "scene.toml")
    truth = json.loads((folder / "truth.json").read_text())
    assert spec.site is None
    for name, detail in truth["photos_detail"].items():
        assert spec.photos[name].sun_elevation_deg == pytest.approx(detail["sun_elevation_deg"] + sun.sun_offset_deg[1])


def test_receivers_of_a_draw_are_written(tmp_path):
    bank = _tiny(4, receivers={"depth": 1.0}, elevation_deg=(40.0, 60.0), meshes=("pillar",))
    assert bank.receiver_shape == "bank"
    folder = synthesize_draw(bank, tmp_path / "bank", render_quality=FAST)
    spec = load_scene(folder / "scene.toml")
    assert spec.receiver.kind == "depth"
    for photo in spec.photos.values():
        depth = np.load(folder / photo.depth)
        assert depth.dtype == np.float32 and np.isfinite(depth).mean() > 0.5
    wall = _tiny(5, receivers={"mesh": 1.0}, elevation_deg=(25.0, 40.0), meshes=("pillar",))
    assert wall.receiver_shape in ("steps", "wall")
    folder = synthesize_draw(wall, tmp_path / "mesh", render_quality=FAST)
    assert load_scene(folder / "scene.toml").receiver.kind == "mesh" and (folder / "receiver.ply").exists()
    # A sun so high that the pillar's shadow ends within its own reach: the ground instead.
    high = _tiny(6, receivers={"mesh": 1.0}, elevation_deg=(84.0, 85.0), meshes=("pillar",),
                 object_scale=(0.75, 0.76))
    assert high.receiver_shape == "plane" and high.receiver_fallback


@functools.lru_cache(maxsize=1)
def _base_draw() -> dict:
    return _tiny(0, receivers={"plane": 1.0}, photos=(3, 3), sun_sources={"time+site": 1.0},
                 meshes=("pillar",), elevation_deg=(39.0, 41.0), well_described_share=1.0).to_json()


def _record(k, sk, rho, sr, *, kt=0.005, rt=0.2, reliable=True, ident=True, error=None, draw=None):
    base = {**_base_draw(), "range_k": kt, "rho": rt}
    return {"seed": 0, "index": 0, "draw": {**base, **(draw or {})}, "k_true": kt, "rho_true": rt,
            "result": {"range_k": k, "range_stderr": sk, "rho": rho, "rho_stderr": sr, "reliable": reliable,
                       "identifiable": ident, "warnings": [], "error": error}}


def test_tables_from_hand_made_records():
    recs = [
        _record(0.0051, 0.0005, 0.201, 0.002),                      # covered
        _record(0.0062, 0.0005, 0.200, 0.002),                      # k 2.4 sigma high: not covered, no miss
        _record(0.0050, 0.0005, 0.209, 0.002),                      # rho 4.5 sigma: confident miss
        _record(0.0080, 0.0010, 0.200, 0.002, ident=False),         # a bound above the truth: covered
        _record(0.0045, 0.0002, 0.200, 0.002, ident=False),         # bound 0.0045 < 0.005 - 0.0002 ... miss
        _record(0.0049, 0.0002, 0.200, 0.002, ident=False),         # under the truth by less than sigma: not covered
        _record(0.0090, 0.0001, 0.300, 0.001, reliable=False),      # flagged: a false alarm (well described)
        _record(None, None, None, None, reliable=True, error="fit failed"),  # an error is flagged whatever it says
        _record(0.0100, 0.0001, 0.250, 0.001, reliable=False, draw={"misdescription": "scale", "mesh": "ball"}),
    ]
    js = [judge(r) for r in recs]
    assert js[0].k_covered and js[0].rho_covered and not js[0].confident_miss
    assert js[1].k_covered is False and js[1].k_pull == pytest.approx(2.4) and not js[1].confident_miss
    assert js[1].k_miss_kind == "high"
    assert js[2].rho_covered is False and js[2].confident_miss
    assert js[3].k_covered and js[3].k_pull is None and not js[3].identifiable
    assert js[4].k_covered is False and js[4].confident_miss and js[4].k_miss_kind == "above bound"
    assert js[5].k_covered is False and not js[5].confident_miss
    assert js[6].flagged and js[6].k_covered is None and js[6].well_described
    assert js[7].flagged and not js[7].fitted and not js[7].reliable
    assert not js[8].well_described
    s = summarize(recs)
    assert (s["groups"], s["reliable"], s["flagged"]) == (9, 6, 3)
    assert (s["k_covered"], s["rho_covered"], s["k_bounds"]) == (3, 5, 3)
    assert s["k_coverage"] == pytest.approx(0.5) and s["rho_coverage"] == pytest.approx(5 / 6, abs=1e-4)
    assert (s["confident_misses"], s["well_described"], s["well_described_flagged"]) == (2, 8, 2)
    assert s["false_alarms"] == 0  # neither flagged well-described group had its values right
    assert judge(_record(0.0050, 0.0005, 0.200, 0.002, reliable=False)).values_covered
    assert summarize([_record(0.0050, 0.0005, 0.200, 0.002, reliable=False)])["false_alarms"] == 1
    assert s["confident_miss_share"] == pytest.approx(2 / 9, abs=1e-4)
    mesh = {row["bin"]: row for row in bin_table(recs, "mesh")}
    assert list(mesh) == ["pillar", "ball", "knot", "dragon"]
    assert (mesh["pillar"]["groups"], mesh["ball"]["groups"], mesh["knot"]["groups"]) == (8, 1, 0)
    assert mesh["knot"]["k_coverage"] is None
    assert bin_table(recs, "misdescription")[1]["groups"] == 1
    c = criteria(recs)
    assert not c["confident_misses_ok"] and c["false_alarms_ok"] and not c["met"]
    assert not criteria([_record(0.0050, 0.0005, 0.200, 0.002, reliable=False)])["false_alarms_ok"]
    assert c["coverage_ok"]  # no bin holds 20 reliable groups
    assert c["coverage_bins_judged"] == [] and not c["size_ok"]  # 9 groups, not the 300 asked for
    many = [_record(0.0051, 0.0005, 0.201, 0.002) for _ in range(19)] + [_record(0.0070, 0.0005, 0.2, 0.002)] * 3
    c = criteria(many)
    assert not c["coverage_ok"] and {f["what"] for f in c["coverage_bins_failing"]} == {"k"}
    assert {"factor": "all", "bin": "all"} in c["coverage_bins_judged"]


def test_a_record_is_judged_again_from_what_the_rule_book_saw():
    """A record keeps the evidence and context the rule book judged (as JSON, NaN included):
    ``coverage_rejudge`` rebuilds them and gives what ``judge_fit`` gives, and states the errors
    with another systematic floor when asked."""
    import dataclasses

    from benchmarks.coverage_rejudge import context_from_json, evidence_from_json, rejudge
    from fitting.solve.uncertainty import SystematicFloor, systematic_errors
    from fitting.verdict.evidence import FitEvidence, GroupContext, LevelOfDetail, PhotoEvidence, SunCheck, SunFree
    from fitting.verdict.rules import judge_fit

    photos = tuple(PhotoEvidence(f"{i}.jpg", 1300, 700, 300, 80, 0.02, rms_lit=0.02, noise_lit=0.02,
                                 misfit=0.9 + 0.1 * i, shadow_depth=0.8, predicted_depth=0.8, depth_gap=0.0, k=0.0057,
                                 k_stderr=0.0002, rho=0.16, rho_stderr=0.001) for i in range(3))
    fit = FitEvidence(k=0.0057, rho=0.159, k_stderr_stat=0.00015, rho_stderr_stat=0.0006, k_stderr_sys=0.0005,
                      rho_stderr_sys=0.002, penumbra_px=2.3, blur_px=None, n_in_penumbra=260, n_in_umbra=900,
                      n_profiles=300, converged=True, range_k_max=0.03, photos=photos,
                      photos_without_shadow=(("d.jpg", "out of view"),),
                      sun_free=SunFree(0.4, 0.9, 0.0064, 0.161, elevation_deg=40.0), receiver="depth")
    context = GroupContext(4, (("e.jpg", "misfit"),), LevelOfDetail(1000, 26600, True, 0.2, float("nan")),
                           SunCheck(0.5, 0.8, 1.1, 1.0, 0.006, 40.0, (0.2, -0.1)))
    inputs = json.loads(json.dumps({"evidence": dataclasses.asdict(fit), "context": dataclasses.asdict(context)}))
    # NaN is not equal to itself: compare the records as JSON.
    assert json.dumps(dataclasses.asdict(evidence_from_json(inputs["evidence"]))) == json.dumps(dataclasses.asdict(fit))
    assert json.dumps(dataclasses.asdict(context_from_json(inputs["context"]))) == json.dumps(dataclasses.asdict(context))
    record = {"seed": 0, "index": 1, "verdict_inputs": inputs, "result": {"reliable": True, "warnings": []}}
    estimate, verdict = judge_fit(fit, context)
    again = rejudge(record)["result"]
    assert (again["reliable"], again["identifiable"], again["warnings"]) == (
        verdict.reliable, verdict.identifiable, list(verdict.warnings))
    assert not again["reliable"]  # the sun moved 1 deg and k followed it
    assert (again["range_k"], again["range_stderr"], again["rho_stderr"]) == (
        estimate.range_k, estimate.range_stderr, estimate.rho_stderr)
    wide = SystematicFloor(0.5, 0.0, 0.02, 0.0)
    widened = rejudge(record, wide)["result"]
    assert widened["range_stderr_sys"] == pytest.approx(systematic_errors(0.0057, 0.159, 2.3, wide)[0])
    assert widened["rho_stderr"] > again["rho_stderr"]
    failed = {"seed": 0, "index": 2, "result": {"error": "fit failed", "reliable": False}}
    assert rejudge(failed) is failed


def test_parse_indices():
    assert parse_indices("3,17,40-42") == [3, 17, 40, 41, 42]
    assert parse_indices(None) is None


def test_report_is_made_from_the_json_alone(tmp_path):
    from softshadow_cli.main import main
    recs = [_record(0.0051, 0.0005, 0.201, 0.002), _record(0.0050, 0.0005, 0.209, 0.002)]
    for i, r in enumerate(recs):
        r["index"] = i
    src = tmp_path / "study.json"
    src.write_text(json.dumps({"seed": 0, "environment": {}, "records": recs}))
    out, report = tmp_path / "again.json", tmp_path / "docs" / "study.md"
    report.parent.mkdir()
    assert main(["bench", "--what", "coverage", "--only", "3,x"]) == 2  # a bad option, before any work
    assert main(["bench", "--what", "coverage", "--from-json", str(tmp_path / "none.json")]) == 2
    assert main(["bench", "--what", "coverage", "--from-json", str(src), "--json", str(out),
                 "--report", str(report)]) == 0
    text = report.read_text()
    assert "Confident misses <= 1% of all groups: **not met** (1 of 2" in text
    assert (tmp_path / "docs" / "img" / "study_coverage.png").stat().st_size > 1000  # named after its page
    assert json.loads(out.read_text())["summary"]["confident_misses"] == 1


def test_a_well_described_small_group_comes_back_covered(tmp_path):
    from benchmarks.coverage import fit_group, _truth_fields
    draw = _tiny(8, elevation_deg=(35.0, 45.0), photos=(2, 2), range_k=(0.007, 0.009), rho=(0.2, 0.35),
                 meshes=("pillar",), receivers={"plane": 1.0}, sun_sources={"time+site": 1.0},
                 well_described_share=1.0, topdown_share=0.0, png_share=0.0, paper_share=1.0,
                 blur_px=(0.5, 0.8), jpeg_quality=(90, 95), frame_shadow_m=(3.0, 3.0))
    folder = synthesize_draw(draw, tmp_path / "g", render_quality=FAST)
    record = {"draw": draw.to_json(), **_truth_fields(folder), **fit_group(folder, draw)}
    j = judge(record)
    assert j.well_described and j.reliable, record["result"]
    assert j.k_covered and j.rho_covered, record["result"]
