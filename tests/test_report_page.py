"""What a fit shows: the overlay in the photo's own pixels, vector plots, the paper's range on its own axis,
and OUT_DIR/index.html with the table, the verdicts, the warnings and every plot."""

from __future__ import annotations

import dataclasses

import numpy as np

from fitting import FitResults, GroupResult
from fitting.report import plots
from fitting.report.results import OverlayPlotData, PlotData, ProfilePlotData
from fitting.report.write import PAPER_TABLE2, write_report


def _group(label="09:20", time="09:20", **kw) -> GroupResult:
    g = GroupResult.from_json(dict(label=label, time=time, photos=["IMG_0001.jpg", "IMG_0002.jpg"], range_k=0.0056,
                                   range_stderr=0.0005, rho=0.157, rho_stderr=0.004, sun_azimuth_deg=120.0,
                                   sun_elevation_deg=45.0, converged=True, **kw))
    d = np.linspace(-8, 8, 200)
    profiles = (ProfilePlotData("IMG_0001.jpg", d, np.clip(0.5 + d / 8, 0.16, 1), np.clip(0.5 + d / 8, 0.16, 1),
                                np.repeat(np.arange(10), 20)),)
    small = np.random.default_rng(0).random((240, 320))
    alpha = np.where(np.arange(320)[None, :] < 160, 1.0, 0.0) * np.ones((240, 1))
    overlays = (OverlayPlotData("IMG_0001.jpg", small, alpha, np.array([[600.0, 470.0], [10.0, 5.0]]),
                                photo_shape=(480, 640)),)
    return dataclasses.replace(g, plots=PlotData(profiles, overlays))


def test_overlay_axes_are_the_photo_pixels_for_a_downsampled_copy():
    fig = plots.overlay_figure(_group(), _group().plot_overlays[0])
    ax = fig.axes[0]
    assert ax.get_xlim() == (-0.5, 639.5)
    assert ax.get_ylim() == (479.5, -0.5)
    offsets = ax.collections[-1].get_offsets()  # the samples, drawn last, in photo pixels
    assert np.allclose(offsets[0], [600.0, 470.0])


def test_overlay_of_a_full_size_image():
    g = _group()
    o = OverlayPlotData("a.png", np.zeros((48, 64)), np.zeros((48, 64)), np.zeros((0, 2)))
    ax = plots.overlay_figure(g, o).axes[0]
    assert ax.get_xlim() == (-0.5, 63.5) and ax.get_ylim() == (47.5, -0.5)


def test_report_writes_index_html_vector_plots_and_the_paper_on_its_own_axis(tmp_path):
    bad = GroupResult.failed("13:21", "13:21", ["IMG_0003.jpg"], "no shadow in view")
    flagged = _group("16:21", "16:21", warnings=["the umbra is not one level"], reliable=False)
    results = FitResults([_group(), bad, flagged], [{"photo": "x.txt", "reason": "not an image"}], {"softshadow": "0"})
    written = write_report(results, tmp_path, reference=PAPER_TABLE2)
    assert "index.html" in written
    assert (tmp_path / "plots" / "09-20_profiles.svg").exists()
    assert (tmp_path / "plots" / "range_vs_time.svg").exists()
    page = (tmp_path / "index.html").read_text()
    for text in ("<table>", "09:20", "no shadow in view", "not reliable", "the umbra is not one level",
                 "x.txt", "plots/09-20_profiles.png", "plots/09-20_overlay_IMG_0001.png", "plots/range_vs_time.png",
                 "0.0056 ± 0.0005"):
        assert text in page, text
    fig_text = (tmp_path / "plots" / "range_vs_time.svg").read_text()
    assert "paper" in fig_text and "own units" in fig_text


def test_index_without_plots_has_no_broken_images(tmp_path):
    results = FitResults([_group()], [], {})
    write_report(results, tmp_path, plots=False)
    page = (tmp_path / "index.html").read_text()
    assert "<img" not in page and "results.json" in page
