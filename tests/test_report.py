"""The report writer: results.json, Table 2 (Markdown, CSV, terminal) and plots.

FitResults are built by hand (no fitting here), so these tests are fast and check
only the writing: exact results.json keys and units, uncertainty propagation,
column order, upper-bound marks, CSV round trip, PNG validity, atomic writes.
"""

from __future__ import annotations

import csv
import dataclasses
import json

import matplotlib.image as mpimg
import numpy as np
import pytest

from fitting.report import plots
from fitting.report import write as report
from fitting.report.write import (PAPER_TABLE2, brightness_stderr, format_table, nearest_paper_time,
                            software_versions, write_report, write_results_json, write_table2)
from fitting.report.results import FitResults, GroupResult, OverlayPlotData, PlotData, ProfilePlotData, Verdict

CONTRACT_GROUP_KEYS = {
    "label", "time", "photos", "range", "range_k", "range_stderr", "brightness", "rho",
    "rho_stderr", "sun_azimuth_deg", "sun_elevation_deg", "rmse", "n_profiles", "converged",
    "identifiable", "seconds"}


def _profiles(photo: str, rho: float = 0.2, n_profiles: int = 6, seed: int = 0) -> ProfilePlotData:
    rng = np.random.default_rng(seed)
    x = np.linspace(-10, 10, 21)
    d, obs, fit, pid = [], [], [], []
    for j in range(n_profiles):
        alpha = np.clip(0.5 - x / (2.0 + 0.5 * j), 0.0, 1.0)
        f = 1.0 - alpha * (1.0 - rho)
        d.append(x), fit.append(f), obs.append(f + rng.normal(0, 0.02, x.size))
        pid.append(np.full(x.size, j))
    return ProfilePlotData(photo, *map(np.concatenate, (d, obs, fit, pid)))


def _overlay(photo: str, h: int = 120, w: int = 160) -> OverlayPlotData:
    """Shadow (alpha = 1) on the right half, lit on the left, unmodelled top rows."""
    yy, xx = np.mgrid[0:h, 0:w]
    alpha = np.clip((xx - w / 2) / 4.0 + 0.5, 0.0, 1.0).astype(float)
    alpha[: h // 10] = np.nan
    image = 0.8 * (1.0 - np.nan_to_num(alpha) * 0.8)
    uv = np.stack([np.full(50, w / 2), np.linspace(h // 10, h - 1, 50)], axis=1)
    return OverlayPlotData(photo, image, alpha, uv)


def _group(label, time, photos, *, profiles=(), overlays=(), **fields) -> GroupResult:
    """A result from its results.json fields (``GroupResult.from_json``) and plot data."""
    g = GroupResult.from_json({"label": label, "time": time, "photos": photos, **fields})
    return dataclasses.replace(g, plots=PlotData(tuple(profiles), tuple(overlays)))


def _results(with_plots: bool = False) -> FitResults:
    """Four groups out of time order: fitted, unidentifiable, failed, no scene."""
    plots = dict(profiles=[_profiles("a.jpg"), _profiles("b.jpg", seed=1)],
                 overlays=[_overlay("a.jpg"), _overlay("b.jpg", 90, 60)]) if with_plots else {}
    morning = _group(
        "09:20", "09:20", ["a.jpg", "b.jpg"], range_k=0.0052, range_stderr=0.0003, rho=0.157,
        rho_stderr=0.002, sun_azimuth_deg=124.2, sun_elevation_deg=49.0, rmse=0.004,
        n_profiles=64, converged=True, identifiable=True, seconds=0.81234, **plots)
    noon = _group("13:21", "13:21", ["c.jpg"], range_k=0.001, range_stderr=0.004, rho=0.2,
                  rho_stderr=0.003, n_profiles=40, converged=True, identifiable=False)
    evening = GroupResult.failed("16:21", "16:21", ["d.jpg"], "no shadow in view")
    no_scene = _group("IMG_7.jpg", None, ["IMG_7.jpg"], rho=0.3, rho_stderr=0.01,
                      penumbra_px=3.4, penumbra_px_iqr=1.2, converged=True)
    return FitResults([evening, no_scene, noon, morning],
                      [{"photo": "bad.jpg", "reason": "not an image: cannot decode"}], {})


TRUTH = {"groups": [{"label": "09:20", "range_k": 0.0047, "rho": 0.16, "sun_azimuth_deg": 124.0,
                     "sun_elevation_deg": 49.0, "photos": ["a.jpg", "b.jpg"]},
                    {"label": "noon", "range_k": 0.0047, "rho": 0.21, "photos": ["c.jpg"]}],
         "renderer": "physical", "preset": "table2"}


# --------------------------------------------------------------------------- results.json

def test_results_json_has_conventions_keys_and_paper_units(tmp_path):
    path = write_results_json(_results(), tmp_path)
    assert path == tmp_path / "results.json"
    doc = json.loads(path.read_text())
    assert set(doc) == {"groups", "skipped", "software"}
    assert doc["skipped"] == [{"photo": "bad.jpg", "reason": "not an image: cannot decode"}]
    assert {"softshadow", "jax", "optimistix", "numpy", "opencv"} <= set(doc["software"])
    assert doc["software"]["numpy"] == np.__version__
    by_label = {g["label"]: g for g in doc["groups"]}
    for g in doc["groups"]:
        assert CONTRACT_GROUP_KEYS <= set(g), CONTRACT_GROUP_KEYS - set(g)
    m = by_label["09:20"]
    assert m["range"] == pytest.approx(100 * 0.0052, rel=1e-12)
    assert m["brightness"] == pytest.approx(255 * 0.157 ** (1 / 2.2), rel=1e-12)
    assert (m["range_k"], m["range_stderr"], m["rho"], m["rho_stderr"]) == (0.0052, 0.0003, 0.157, 0.002)
    assert m["photos"] == ["a.jpg", "b.jpg"] and m["converged"] is True and m["identifiable"] is True
    assert by_label["13:21"]["identifiable"] is False
    failed = by_label["16:21"]
    assert failed["error"] == "no shadow in view" and failed["range"] is None and failed["rho"] is None
    ns = by_label["IMG_7.jpg"]
    assert ns["range_k"] is None and ns["penumbra_px"] == 3.4 and ns["penumbra_px_iqr"] == 1.2


def test_results_json_keeps_given_software_and_rejects_nan(tmp_path):
    results = _results()
    results.software = {"softshadow": "9.9"}
    doc = json.loads(write_results_json(results, tmp_path).read_text())
    assert doc["software"] == {"softshadow": "9.9"}
    results.skipped = [{"photo": "x.jpg", "reason": "bad", "value": float("nan")}]
    with pytest.raises(ValueError):
        write_results_json(results, tmp_path)
    # The failed write left the previous file and no temporary file behind.
    assert json.loads((tmp_path / "results.json").read_text()) == doc
    assert sorted(p.name for p in tmp_path.iterdir()) == ["results.json"]


def test_results_json_write_is_atomic(tmp_path, monkeypatch):
    old = write_results_json(_results(), tmp_path).read_bytes()

    def dump_half_then_crash(obj, fh, **kwargs):
        fh.write('{"groups": [')  # a partial document reaches the temporary file
        fh.flush()
        raise RuntimeError("simulated crash while writing")

    monkeypatch.setattr(json, "dump", dump_half_then_crash)
    changed = _results()
    g = changed.groups[3]
    changed.groups[3] = dataclasses.replace(g, estimate=dataclasses.replace(g.estimate, rho=0.5))
    with pytest.raises(RuntimeError, match="simulated crash"):
        write_results_json(changed, tmp_path)
    assert (tmp_path / "results.json").read_bytes() == old
    assert sorted(p.name for p in tmp_path.iterdir()) == ["results.json"]


def test_software_versions_keys():
    v = software_versions()
    assert set(v) == {"softshadow", "jax", "optimistix", "numpy", "opencv"}
    import jax
    assert v["jax"] == jax.__version__ and v["numpy"] == np.__version__
    assert v["opencv"] is not None


# --------------------------------------------------------------------------- uncertainty

@pytest.mark.parametrize("rho", [0.02, 0.157, 0.5, 0.97])
def test_brightness_stderr_matches_finite_difference(rho):
    h = 1e-7
    slope = (255 * (rho + h) ** (1 / 2.2) - 255 * (rho - h) ** (1 / 2.2)) / (2 * h)
    assert brightness_stderr(rho, 0.003) == pytest.approx(slope * 0.003, rel=1e-6)


def test_brightness_stderr_undefined_cases():
    assert brightness_stderr(0.0, 0.01) is None
    assert brightness_stderr(0.2, None) is None
    assert brightness_stderr(None, 0.01) is None


# --------------------------------------------------------------------------- Table 2

def _md_table(md: str) -> list[list[str]]:
    rows = [line for line in md.splitlines() if line.startswith("|")]
    return [[c.strip() for c in line.strip("|").split(" | ")] for line in rows]


def test_table2_markdown_columns_bounds_failures(tmp_path):
    md_path, csv_path = write_table2(_results(), tmp_path)
    assert (md_path, csv_path) == (tmp_path / "table2.md", tmp_path / "table2.csv")
    md = md_path.read_text()
    table = _md_table(md)
    header = table[0]
    # One column per group in time order, the untimed group last.
    assert header == ["Time of day", "09:20", "13:21", "16:21", "IMG_7.jpg"]
    rows = {r[0]: r[1:] for r in table[2:]}
    assert all(len(r) == 4 for r in rows.values())
    rng = rows["Range of the soft shadow (100 k)"]
    bright = rows["Brightness of the shadow (255 ρ^(1/2.2))"]
    assert rng[0] == "0.520 ± 0.030"
    assert rng[1].startswith("≤ 0.10") and "±" not in rng[1]
    assert rows["k (physical range)"][1].startswith("≤ 0.00100")
    assert rng[2].startswith("—") and bright[2] == "—"
    # Brightness 255 * 0.157^(1/2.2) = 109.91, its stderr 0.64 (propagated).
    assert bright[0] == "109.91 ± 0.64"
    assert rows["ρ (physical brightness)"][0] == "0.1570 ± 0.0020"
    assert rows["Penumbra width (px, median; ± is the IQR)"][3] == "3.4 ± 1.2"
    # Footnotes: the upper bound, the failure's reason, the no-scene group; skipped photo.
    assert "16:21: not fitted: no shadow in view" in md
    assert "upper bound" in md and "IMG_7.jpg: no scene geometry" in md
    assert "bad.jpg: not an image" in md
    mark = rng[1].split()[-1]
    note_number = mark.strip("[]")
    assert any(line.startswith(f"{note_number}. upper bound") for line in md.splitlines())


def test_table2_reference_and_truth_rows(tmp_path):
    results = _results()
    results.groups[3] = dataclasses.replace(results.groups[3], time="09:41")  # 21 minutes from 09:20: still matched
    md_path, _ = write_table2(results, tmp_path, reference=PAPER_TABLE2, truth=TRUTH)
    rows = {r[0]: r[1:] for r in _md_table(md_path.read_text())[2:]}
    assert rows["Paper, set by hand: range (its own units)"] == ["6.0", "5.0", "8.0", "—"]
    assert rows["Paper, set by hand: brightness"] == ["110.0", "120.0", "180.0", "—"]
    assert rows["Truth: range"][:2] == ["0.47", "0.47"]  # matched by photos, not label
    assert rows["Truth: brightness"][0] == f"{255 * 0.16 ** (1 / 2.2):.1f}"
    assert rows["Truth: ρ"][1] == "0.210"


def test_table2_csv_round_trip(tmp_path):
    results = _results()
    _, csv_path = write_table2(results, tmp_path, reference=PAPER_TABLE2, truth=TRUTH)
    with open(csv_path, newline="", encoding="utf-8") as fh:
        rows = list(csv.reader(fh))
    header = rows[0]
    assert header == ["quantity", "09:20", "09:20 stderr", "13:21", "13:21 stderr",
                      "16:21", "16:21 stderr", "IMG_7.jpg", "IMG_7.jpg stderr"]
    table = {r[0]: dict(zip(header[1:], r[1:])) for r in rows[1:]}
    by_label = {g.label: g for g in results.groups}
    for label in ("09:20", "13:21"):
        g = by_label[label]
        assert float(table["range"][label]) == g.range
        assert float(table["range"][f"{label} stderr"]) == pytest.approx(100 * g.range_stderr, rel=1e-15)
        assert float(table["range_k"][label]) == g.range_k
        assert float(table["range_k"][f"{label} stderr"]) == g.range_stderr
        assert float(table["rho"][label]) == g.rho
        assert float(table["rho"][f"{label} stderr"]) == g.rho_stderr
        assert float(table["brightness"][label]) == g.brightness
        assert float(table["brightness"][f"{label} stderr"]) == brightness_stderr(g.rho, g.rho_stderr)
    assert table["range_is_upper_bound"]["09:20"] == "false"
    assert table["range_is_upper_bound"]["13:21"] == "true"
    assert table["range"]["16:21"] == "" and table["error"]["16:21"] == "no shadow in view"
    assert table["range"]["IMG_7.jpg"] == "" and float(table["penumbra_px"]["IMG_7.jpg"]) == 3.4
    assert float(table["penumbra_px"]["IMG_7.jpg stderr"]) == 1.2
    assert table["time"]["09:20"] == "09:20" and table["time"]["IMG_7.jpg"] == ""
    assert float(table["reference_brightness"]["16:21"]) == 180.0
    assert float(table["truth_range_k"]["09:20"]) == 0.0047


def test_nearest_paper_time():
    assert nearest_paper_time("09:20") == "09:20"
    assert nearest_paper_time("9:45") == "09:20"       # 25 minutes
    assert nearest_paper_time("09:51") is None          # 31 minutes
    assert nearest_paper_time("13:00") == "13:21"
    assert nearest_paper_time("16:40:10") == "16:21"
    assert nearest_paper_time(None) is None
    assert nearest_paper_time("IMG_7.jpg") is None


def test_format_table_shows_fit_truth_and_paper():
    text = format_table(_results(), reference=PAPER_TABLE2, truth=TRUTH)
    lines = text.splitlines()
    assert lines[0].split() == ["Time", "of", "day", "09:20", "13:21", "16:21", "IMG_7.jpg"]
    assert any(line.startswith("Paper, set by hand: brightness") and "110.0" in line and "180.0" in line
               for line in lines)
    assert any(line.startswith("Truth: range") and "0.47" in line for line in lines)
    assert "≤ 0.10" in text and "no shadow in view" in text
    # Columns are aligned: every table row is as wide as the header's last column ends.
    width = len(lines[0])
    assert all(len(line) == width for line in lines[1:8])
    assert format_table(FitResults([], [], {})) == "No groups were fitted.\n"


# --------------------------------------------------------------------------- plots

def _png(path):
    img = mpimg.imread(path)
    assert img.ndim == 3 and img.shape[0] >= 200 and img.shape[1] >= 300, img.shape
    assert img[..., :3].std() > 0.05  # not a blank canvas
    return img


def test_plot_group_writes_profiles_and_overlays(tmp_path):
    group = _results(with_plots=True).groups[3]
    paths = plots.plot_group(group, tmp_path)
    assert [p.name for p in paths] == ["09-20_profiles.png", "09-20_overlay_a.png",
                                       "09-20_overlay_b.png"]
    for p in paths:
        assert p.parent == tmp_path / "plots"
        _png(p)
    assert not [p for p in (tmp_path / "plots").iterdir() if p.name.startswith(".")]


def test_overlay_draws_alpha_where_the_shadow_is(tmp_path):
    """The fitted alpha is drawn as a red tint: the shadowed half of the plot is redder."""
    group = _group("g", None, ["s.png"], rho=0.2, overlays=[_overlay("s.png", 200, 200)])
    (path,) = plots.plot_group(group, tmp_path)
    img = _png(path)[..., :3]
    redness = img[..., 0] - img[..., 1]
    # The axes box sits in the middle of the figure; sample its left and right quarters.
    h, w = redness.shape
    band = slice(int(0.45 * h), int(0.7 * h))
    lit, shade = redness[band, int(0.25 * w):int(0.4 * w)], redness[band, int(0.6 * w):int(0.75 * w)]
    assert shade.mean() > lit.mean() + 0.1


def test_overlay_of_a_big_photo_is_drawn_with_a_stride(tmp_path, monkeypatch):
    """A 1600x1200 photo reaches matplotlib strided to MAX_OVERLAY_SIDE (drawing it whole
    took seconds per plot), with its axes still in the photo's pixels."""
    from matplotlib.axes import Axes
    drawn = []
    imshow = Axes.imshow

    def spy(self, x, *args, **kwargs):
        drawn.append((np.shape(x), kwargs.get("extent")))
        return imshow(self, x, *args, **kwargs)

    monkeypatch.setattr(Axes, "imshow", spy)
    group = _group("09:20", "09:20", ["big.jpg"], overlays=[_overlay("big.jpg", 1200, 1600)])
    (path,) = plots.plot_group(group, tmp_path)
    assert drawn and all(max(shape[:2]) <= plots.MAX_OVERLAY_SIDE for shape, _ in drawn)
    assert all(extent[1] >= 1600 - 1 and extent[2] >= 1200 - 1 for _, extent in drawn)
    _png(path)


def test_plots_skip_empty_data(tmp_path):
    empty = GroupResult.failed("x", None, ["x.jpg"], "board not found")
    assert plots.plot_group(empty, tmp_path) == []
    blank = _group("y", None, ["y.jpg"], profiles=[ProfilePlotData(
        "y.jpg", np.empty(0), np.empty(0), np.empty(0), np.empty(0, int))],
        overlays=[OverlayPlotData("y.jpg", np.empty((0, 0)), np.empty((0, 0)), np.empty((0, 2)))])
    assert plots.plot_group(blank, tmp_path) == []
    no_time = FitResults([_group("IMG_7.jpg", None, ["IMG_7.jpg"], rho=0.3)], [], {})
    assert plots.plot_range_vs_time(no_time, tmp_path) is None


def test_overlays_with_one_stem_do_not_overwrite(tmp_path):
    group = _group("g", None, ["a.jpg", "a.dng"], overlays=[_overlay("a.jpg"), _overlay("a.dng")])
    assert [p.name for p in plots.plot_group(group, tmp_path)] == ["g_overlay_a.png", "g_overlay_a_2.png"]


def test_range_vs_time_plot(tmp_path):
    path = plots.plot_range_vs_time(_results(), tmp_path, reference=PAPER_TABLE2, truth=TRUTH)
    assert path == tmp_path / "plots" / "range_vs_time.png"
    _png(path)


def test_safe_name():
    assert plots.safe_name("09:20") == "09-20"
    assert plots.safe_name("morning / west") == "morning___west"
    assert plots.safe_name("..") == "group"


# --------------------------------------------------------------------------- everything

def test_write_report_writes_everything(tmp_path):
    written = write_report(_results(with_plots=True), tmp_path, reference=PAPER_TABLE2, truth=TRUTH)
    assert set(written) == {"results.json", "table2.md", "table2.csv", "index.html", "plots/09-20_profiles.png",
                            "plots/09-20_overlay_a.png", "plots/09-20_overlay_b.png",
                            "plots/range_vs_time.png"}
    for rel, path in written.items():
        assert path == tmp_path / rel and path.stat().st_size > 0
    assert "Paper, set by hand: range" in (tmp_path / "table2.md").read_text()


def test_write_report_survives_a_failing_plot(tmp_path, monkeypatch, caplog):
    def broken(group, out_dir):
        raise ValueError("bad plot data")

    monkeypatch.setattr(plots, "plot_group", broken)
    written = write_report(_results(with_plots=True), tmp_path)
    assert {"results.json", "table2.md", "table2.csv"} <= set(written)
    assert "bad plot data" in caplog.text
    assert report.PAPER_TABLE2["13:21"] == (5.0, 120.0)


def test_write_report_without_plots(tmp_path):
    written = write_report(_results(with_plots=True), tmp_path, plots=False)
    assert set(written) == {"results.json", "table2.md", "table2.csv", "index.html"}
    assert not (tmp_path / "plots").exists()


def test_profile_plot_view_ignores_far_outliers():
    """A fifth of the samples parked at +-1000 px must not squeeze the edge into a line."""
    d = np.concatenate([np.linspace(-10, 10, 80), np.full(10, 1000.0), np.full(10, -1000.0)])
    half = plots._view_half_width(d)
    assert 10.0 <= half <= 40.0
    assert plots._view_half_width(np.linspace(-2, 2, 9)) == 2.0
    assert plots._view_half_width(np.array([np.nan])) == 5.0


def test_written_files_have_ordinary_permissions(tmp_path):
    import os
    mask = os.umask(0o022)
    os.umask(mask)
    for path in write_report(_results(), tmp_path, plots=False).values():
        assert path.stat().st_mode & 0o777 == 0o666 & ~mask


def test_an_unreliable_group_says_so_in_the_table_and_csv(tmp_path):
    results = _results()
    g = results.groups[3] = dataclasses.replace(results.groups[3], verdict=Verdict(
        reliable=False, identifiable=True, warnings=("edges disagree: measured rho 0.200 (30 profiles), "
                                                     "another mode at rho 0.550 (20 profiles)",)))
    md_path, csv_path = write_table2(results, tmp_path)
    md = md_path.read_text()
    assert f"{g.label}: NOT RELIABLE: edges disagree: measured rho 0.200 (30 profiles)" in md
    assert "NOT RELIABLE" in format_table(results)
    with open(csv_path, newline="", encoding="utf-8") as fh:
        rows = list(csv.reader(fh))
    reliable = dict(zip(rows[0][1:], next(r for r in rows if r[0] == "reliable")[1:]))
    assert reliable[g.label] == "false"
    assert all(reliable[o.label] in ("true", "") for o in results.groups if o is not g)
