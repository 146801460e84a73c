"""Plots of a fit (PNG, matplotlib's Agg canvas, no pyplot state).

- ``plot_group``: per group, observed against fitted values across the shadow edge
  (OUT_DIR/plots/<label>_profiles.png) and the fitted shadow over each photo
  (OUT_DIR/plots/<label>_overlay_<photo stem>.png).
- ``plot_range_vs_time``: range and brightness against time of day
  (OUT_DIR/plots/range_vs_time.png).
- ``plot_folders_vs_time``: k and rho against time of day across many folders
  (OUT/summary.png of ``fitting.fit_many``).

Figures are built on ``matplotlib.figure.Figure`` directly, so plotting works in
threads and never touches the user's pyplot backend.
"""

from __future__ import annotations

import math
from pathlib import Path
from collections.abc import Mapping

import numpy as np
from matplotlib.collections import LineCollection
from matplotlib.figure import Figure
from matplotlib.ticker import FuncFormatter, MultipleLocator
from matplotlib.transforms import offset_copy

from .comparison import (brightness_stderr, groups_in_time_order, minutes_of_day, range_stderr_paper,
                         reference_for_group, truth_for_group)
from softshadow import brightness_to_paper, range_to_paper
from .files import atomic_path, safe_name
from .results import FitResults, GroupResult, OverlayPlotData, ProfilePlotData

__all__ = ["safe_name", "plot_group", "plot_profiles", "plot_overlay", "overlay_figure", "plot_range_vs_time",
           "plot_folders_vs_time", "MAX_OVERLAY_SIDE"]

#: Overlays show the photo downsampled to at most this many pixels on its longer side.
MAX_OVERLAY_SIDE = 800
#: At most this many individual profiles are drawn as lines per photo (the rest only as dots).
MAX_PROFILE_LINES = 60
#: PNG resolution (dots per inch of the figure's size).
_DPI = 150


def _plots_dir(out_dir) -> Path:
    path = Path(out_dir) / "plots"
    path.mkdir(parents=True, exist_ok=True)
    return path


def _fixed_margins(fig: Figure, left: float, right: float, bottom: float, top: float,
                   **spacing) -> None:
    """Margins in inches (a fixed layout: a constrained one costs an extra draw per figure)."""
    w, h = fig.get_size_inches()
    fig.subplots_adjust(left=left / w, right=1 - right / w, bottom=bottom / h, top=1 - top / h,
                        **spacing)


def _save(fig: Figure, path: Path, vector: bool = False) -> Path:
    """Save atomically (temporary name in the same folder, then replace) as PNG, and as SVG beside it
    when ``vector`` (plots of points and lines; an overlay is a photo, a raster either way)."""
    with atomic_path(path) as tmp:
        # Light PNG compression: several times faster to write, files somewhat larger.
        fig.savefig(tmp, dpi=_DPI, format="png", pil_kwargs={"compress_level": 1})
    if vector:
        with atomic_path(path.with_suffix(".svg")) as tmp:
            fig.savefig(tmp, format="svg")
    return path


def _has_profile_data(p: ProfilePlotData) -> bool:
    return np.asarray(p.distance_px).size > 0 and np.asarray(p.observed).size > 0


def _has_overlay_data(o: OverlayPlotData) -> bool:
    image = np.asarray(o.image)
    return image.ndim >= 2 and image.shape[0] > 0 and image.shape[1] > 0


# --------------------------------------------------------------------------- profiles

def _binned_median(x: np.ndarray, y: np.ndarray, n_bins: int = 40) -> tuple[np.ndarray, np.ndarray]:
    """Median of y in equal-width bins of x (bins with no sample dropped)."""
    ok = np.isfinite(x) & np.isfinite(y)
    x, y = x[ok], y[ok]
    if x.size == 0:
        return np.empty(0), np.empty(0)
    edges = np.linspace(x.min(), x.max(), n_bins + 1)
    which = np.clip(np.digitize(x, edges) - 1, 0, n_bins - 1)
    centres, medians = [], []
    for b in range(n_bins):
        sel = which == b
        if sel.any():
            centres.append(0.5 * (edges[b] + edges[b + 1]))
            medians.append(np.median(y[sel]))
    return np.asarray(centres), np.asarray(medians)


def _view_half_width(distance_px: np.ndarray) -> float:
    """Half-width (px) of the x range shown: 3 times the median |distance|, so that the
    edge fills the panel even when a few samples lie far away (the fitter may park
    samples with no local distance at a large clip value), at least 5 px, at most the
    farthest sample."""
    a = np.abs(distance_px[np.isfinite(distance_px)])
    if a.size == 0:
        return 5.0
    return float(min(a.max(), max(5.0, 3.0 * np.median(a))))


def plot_profiles(group: GroupResult, out_dir) -> Path | None:
    """OUT_DIR/plots/<label>_profiles.png: per photo, observed (dots) and fitted values
    against the signed distance to the fitted boundary (px, positive = lit), the
    individual observed profiles as faint lines and binned medians of both as lines.
    None when the group has no profile data."""
    data = [p for p in group.plot_profiles if _has_profile_data(p)]
    if not data:
        return None
    n = len(data)
    cols = min(n, 3)
    rows = math.ceil(n / cols)
    fig = Figure(figsize=(4.2 * cols, 3.2 * rows + 0.4))
    _fixed_margins(fig, left=0.75, right=0.15, bottom=0.55, top=0.75, wspace=0.08, hspace=0.45)
    axes = fig.subplots(rows, cols, squeeze=False, sharey=True)
    for ax, p in zip(axes.flat, data):
        d = np.asarray(p.distance_px, float).ravel()
        obs = np.asarray(p.observed, float).ravel()
        fit = np.asarray(p.fitted, float).ravel()
        ids = np.asarray(p.profile_id).ravel()
        half_width = _view_half_width(d)
        keep = np.abs(d) <= half_width
        n_out = int(np.count_nonzero(~keep & np.isfinite(d)))
        same = d.size
        d, obs = d[keep], obs[keep]
        fit = fit[keep] if fit.size == same else fit
        ids = ids[keep] if ids.size == same else ids
        if ids.size == d.size:
            lines = []
            for pid in np.unique(ids)[:MAX_PROFILE_LINES]:
                sel = ids == pid
                order = np.argsort(d[sel])
                lines.append(np.column_stack([d[sel][order], obs[sel][order]]))
            # One collection, not one artist per profile: drawing cost stays flat.
            ax.add_collection(LineCollection(lines, colors="0.6", linewidths=0.5, alpha=0.35,
                                             zorder=1))
        ax.scatter(d, obs, s=3, color="tab:blue", alpha=0.35, lw=0, label="observed", zorder=2)
        if fit.size == d.size:
            ax.scatter(d, fit, s=2, color="tab:orange", alpha=0.5, lw=0, label="fitted", zorder=3)
            ax.plot(*_binned_median(d, fit), color="tab:red", lw=1.5, label="fitted (median)", zorder=5)
        ax.plot(*_binned_median(d, obs), color="navy", lw=1.5, label="observed (median)", zorder=4)
        ax.axvline(0.0, color="k", lw=0.6, ls="--")
        ax.set_xlim(-half_width, half_width)
        title = p.photo if not n_out else f"{p.photo} ({n_out} samples beyond ±{half_width:.0f} px not shown)"
        ax.set_title(title, fontsize=9)
        ax.set_xlabel("signed distance to boundary [px] (lit > 0)")
        ax.grid(alpha=0.3)
    for ax in axes[:, 0]:
        ax.set_ylabel("value / lit level (linear)")
    for ax in list(axes.flat)[n:]:
        ax.set_visible(False)
    axes.flat[0].legend(fontsize=7, loc="lower right", markerscale=3)
    fig.suptitle(_group_title(group), fontsize=10)
    return _save(fig, _plots_dir(out_dir) / f"{safe_name(group.label)}_profiles.png", vector=True)


def _group_title(g: GroupResult) -> str:
    parts = [g.label if g.time in (None, g.label) else f"{g.label} ({g.time})"]
    if g.range_k is not None:
        bound = "≤ " if not g.identifiable else ""
        parts.append(f"range {bound}{g.range:.2f} (k {bound}{g.range_k:.4g})")
    if g.rho is not None:
        parts.append(f"brightness {g.brightness:.1f} (ρ {g.rho:.3g})")
    return ", ".join(parts)


# --------------------------------------------------------------------------- overlay

def _display(image: np.ndarray) -> np.ndarray:
    """Linear gray -> [0, 1] display values: scaled to its 99.5th percentile, sRGB-like
    gamma so shadows stay visible."""
    img = np.asarray(image, float)
    if img.ndim == 3:
        img = img[..., :3].mean(axis=-1)
    finite = img[np.isfinite(img)]
    top = np.percentile(finite, 99.5) if finite.size else 1.0
    top = top if top > 0 else 1.0
    return np.clip(np.nan_to_num(img / top, nan=0.0), 0.0, 1.0) ** (1 / 2.2)


def plot_overlay(group: GroupResult, overlay: OverlayPlotData, out_dir, stem: str | None = None) -> Path | None:
    """OUT_DIR/plots/<label>_overlay_<photo stem>.png (``overlay_figure``); None when there is no image."""
    fig = overlay_figure(group, overlay)
    if fig is None:
        return None
    stem = stem if stem is not None else safe_name(Path(overlay.photo).stem)
    return _save(fig, _plots_dir(out_dir) / f"{safe_name(group.label)}_overlay_{stem}.png")


def overlay_figure(group: GroupResult, overlay: OverlayPlotData) -> Figure | None:
    """The overlay of a group's fit on one photo: the photo in gray, the fitted
    alpha as a translucent colour overlay, the fitted boundary (alpha = 0.5) as a
    contour, and the fit's sample pixels as tiny dots. Big images are shown with a
    stride so the longer side is at most MAX_OVERLAY_SIDE; the axes are the photo's own
    pixels (``overlay.photo_shape``), also when the image is a downsampled copy. None when
    there is no image."""
    if not _has_overlay_data(overlay):
        return None
    image = np.asarray(overlay.image)
    h, w = image.shape[:2]
    photo_h, photo_w = overlay.photo_shape or (h, w)
    step = max(1, math.ceil(max(h, w) / MAX_OVERLAY_SIDE))
    gray = _display(image[::step, ::step])
    # The shown image covers the photo; pixel centres at integers (OpenCV convention).
    sx, sy = photo_w / gray.shape[1], photo_h / gray.shape[0]
    extent = (-0.5, photo_w - 0.5, photo_h - 0.5, -0.5)

    aspect = h / w
    width_in = 7.0
    fig = Figure(figsize=(width_in, width_in * aspect + 0.9))
    _fixed_margins(fig, left=0.7, right=0.2, bottom=0.55, top=0.6)
    ax = fig.subplots()
    ax.imshow(gray, cmap="gray", vmin=0.0, vmax=1.0, extent=extent, interpolation="nearest")

    alpha = np.asarray(overlay.alpha, float)
    if alpha.shape[:2] == (h, w):
        a = alpha[::step, ::step]
        a_clip = np.clip(np.nan_to_num(a, nan=0.0), 0.0, 1.0)
        rgba = np.zeros(a.shape + (4,))
        rgba[..., 0], rgba[..., 2] = 1.0, 0.2  # magenta-red: stands out on gray
        rgba[..., 3] = 0.4 * a_clip * np.isfinite(a)
        ax.imshow(rgba, extent=extent, interpolation="nearest")
        if np.isfinite(a).any() and np.nanmin(a) < 0.5 < np.nanmax(a):
            # The centres of the shown pixels, in photo pixels.
            ys = (np.arange(a.shape[0]) + 0.5) * sy - 0.5
            xs = (np.arange(a.shape[1]) + 0.5) * sx - 0.5
            ax.contour(xs, ys, np.where(np.isfinite(a), a, np.nan), levels=[0.5],
                       colors="yellow", linewidths=0.8)
    uv = np.asarray(overlay.samples_uv, float).reshape(-1, 2) if np.size(overlay.samples_uv) else np.empty((0, 2))
    if len(uv):
        ax.scatter(uv[:, 0], uv[:, 1], s=0.3, color="cyan", lw=0, alpha=0.7)
    ax.set_xlim(extent[0], extent[1])
    ax.set_ylim(extent[2], extent[3])
    ax.set_title(f"{_group_title(group)}\n{overlay.photo}: fitted alpha (red), "
                 f"boundary alpha=0.5 (yellow), samples (cyan)", fontsize=8)
    ax.set_xlabel("u [photo px]")
    ax.set_ylabel("v [photo px]")
    return fig


def plot_group(group: GroupResult, out_dir) -> list[Path]:
    """The profile plot and one overlay per photo of a group; [] when it has no plot data."""
    written = []
    p = plot_profiles(group, out_dir)
    if p is not None:
        written.append(p)
    stems: dict[str, int] = {}
    for overlay in group.plot_overlays:
        stem = safe_name(Path(overlay.photo).stem)
        # Two photos with one stem (a.jpg and a.dng) must not overwrite each other.
        stems[stem] = stems.get(stem, 0) + 1
        if stems[stem] > 1:
            stem = f"{stem}_{stems[stem]}"
        p = plot_overlay(group, overlay, out_dir, stem=stem)
        if p is not None:
            written.append(p)
    return written


# --------------------------------------------------------------------------- range vs time

def _hhmm(minutes: float, _pos=None) -> str:
    minutes = int(round(minutes))
    return f"{minutes // 60:02d}:{minutes % 60:02d}"


def plot_range_vs_time(results: FitResults, out_dir, reference: Mapping | None = None,
                       truth: Mapping | None = None) -> Path | None:
    """OUT_DIR/plots/range_vs_time.png (and .svg): range (100 k) and brightness (255 rho^(1/2.2))
    against time of day, one-sigma error bars, upper bounds as down-arrows; truth values as open
    markers when given, and the paper's hand-set values (``reference``), whose range is on an axis of
    its own. None when no fitted group has a time."""
    groups = [g for g in groups_in_time_order(results.groups) if g.fitted and minutes_of_day(g.time) is not None]
    if not groups:
        return None
    t = np.array([minutes_of_day(g.time) for g in groups])
    fig = Figure(figsize=(6.5, 5.5), layout="constrained")
    ax_r, ax_b = fig.subplots(2, 1, sharex=True)

    # Range: measured points with error bars, upper bounds as arrows pointing down.
    with_range = [(tm, g) for tm, g in zip(t, groups) if g.range_k is not None]
    measured = [(tm, g) for tm, g in with_range if g.identifiable]
    bounds = [(tm, g) for tm, g in with_range if not g.identifiable]
    if measured:
        ax_r.errorbar([tm for tm, _ in measured], [g.range for _, g in measured],
                      yerr=[range_stderr_paper(g) or 0.0 for _, g in measured],
                      fmt="o", color="tab:blue", capsize=3, label="fitted")
    # The arrow's length is fixed in points so it shows whatever the axis range.
    arrow_head = offset_copy(ax_r.transData, fig=fig, y=-24, units="points")
    for tm, g in bounds:
        ax_r.annotate("", xy=(tm, g.range), xycoords=arrow_head, xytext=(tm, g.range),
                      textcoords="data", annotation_clip=False,
                      arrowprops=dict(arrowstyle="-|>", color="tab:blue", lw=1.2,
                                      shrinkA=0, shrinkB=0))
        ax_r.plot([tm], [g.range], marker="_", ms=12, mew=2, color="tab:blue")
    if bounds:
        ax_r.plot([], [], marker="v", ls="", color="tab:blue", label="upper bound")
    if not with_range:
        ax_r.text(0.5, 0.5, "no range: no scene geometry", transform=ax_r.transAxes,
                  ha="center", va="center", color="0.4")

    b_pts = [(tm, g) for tm, g in zip(t, groups) if g.rho is not None]
    ax_b.errorbar([tm for tm, _ in b_pts], [g.brightness for _, g in b_pts],
                  yerr=[brightness_stderr(g.rho, g.rho_stderr) or 0.0 for _, g in b_pts],
                  fmt="o", color="tab:blue", capsize=3, label="fitted")

    refs = [(tm, reference_for_group(g, reference)) for tm, g in zip(t, groups)]
    refs = [(tm, r) for tm, r in refs if r is not None]
    if refs:
        # The paper's ranges were set by hand with its own expansion rule and profile: an order of
        # magnitude above a measured k's 100 k. On their own axis they neither squash the error bars
        # nor read as a miss.
        ax_paper = ax_r.twinx()
        ax_paper.plot([tm for tm, _ in refs], [r[0] for _, r in refs], "s", mfc="none", color="tab:green",
                      label="paper's Table 2 (right axis)")
        ax_paper.set_ylabel("paper's Table 2 range\n(set by hand, its own units)", color="tab:green")
        ax_paper.tick_params(axis="y", colors="tab:green")
        ax_paper.set_ylim(bottom=0.0, top=1.15 * max(r[0] for _, r in refs))
        ax_r.plot([], [], "s", mfc="none", color="tab:green", label="paper's Table 2 (right axis)")
        ax_b.plot([tm for tm, _ in refs], [r[1] for _, r in refs], "s", mfc="none",
                  color="tab:green", label="paper's Table 2")
    truths = [(tm, truth_for_group(g, truth)) for tm, g in zip(t, groups)]
    truths = [(tm, tr) for tm, tr in truths if tr is not None]
    tk = [(tm, tr["range_k"]) for tm, tr in truths if tr.get("range_k") is not None]
    tr_ = [(tm, tr["rho"]) for tm, tr in truths if tr.get("rho") is not None]
    if tk:
        ax_r.plot([a for a, _ in tk], [range_to_paper(k) for _, k in tk], "D", mfc="none",
                  color="tab:red", label="truth")
    if tr_:
        ax_b.plot([a for a, _ in tr_], [brightness_to_paper(max(r, 0.0)) for _, r in tr_], "D",
                  mfc="none", color="tab:red", label="truth")

    ax_r.set_ylabel("range of the soft shadow\n(100 k)")
    ax_b.set_ylabel("brightness of the shadow\n(255 ρ^(1/2.2))")
    ax_r.set_ylim(bottom=0.0)
    ax_b.set_ylim(0.0, 255.0)
    ax_b.set_xlabel("time of day")
    span_h = (t.max() - t.min()) / 60.0
    ax_b.xaxis.set_major_locator(MultipleLocator(60.0 * max(1, math.ceil(span_h / 6))))
    ax_b.xaxis.set_major_formatter(_hhmm)
    pad = max(30.0, 0.1 * (t.max() - t.min()))
    ax_b.set_xlim(t.min() - pad, t.max() + pad)
    for ax in (ax_r, ax_b):
        ax.grid(alpha=0.3)
        if ax.get_legend_handles_labels()[0]:
            ax.legend(fontsize=8)
    return _save(fig, _plots_dir(out_dir) / "range_vs_time.png", vector=True)


def plot_folders_vs_time(summary, path) -> Path | None:
    """A plot across folders (``fitting.fit_many``'s summary, a pandas DataFrame): k and rho
    against time of day, one line per folder with one-sigma error bars. Written to ``path``
    (PNG); None when no fitted group has a time of day."""
    rows = summary[summary["rho"].notna()].copy()
    rows["minutes"] = [minutes_of_day(t) for t in rows["time"]]
    rows = rows[rows["minutes"].notna()]
    if rows.empty:
        return None
    fig = Figure(figsize=(7.5, 5.5), layout="constrained")
    ax_k, ax_rho = fig.subplots(2, 1, sharex=True)
    folders = list(dict.fromkeys(rows["folder"]))
    for folder in folders:
        part = rows[rows["folder"] == folder].sort_values("minutes")
        hours = part["minutes"].to_numpy(float) / 60.0
        k = part["range_k"].to_numpy(float)
        ax_k.errorbar(hours, k, yerr=np.nan_to_num(part["range_stderr"].to_numpy(float)), marker="o",
                      ms=4, capsize=2, lw=1, label=folder)
        ax_rho.errorbar(hours, part["rho"].to_numpy(float),
                        yerr=np.nan_to_num(part["rho_stderr"].to_numpy(float)), marker="o", ms=4,
                        capsize=2, lw=1, label=folder)
    ax_k.set_ylabel("range k")
    ax_rho.set_ylabel("brightness rho")
    ax_rho.set_xlabel("time of day")
    ax_rho.xaxis.set_major_formatter(FuncFormatter(lambda h, _: f"{int(h) % 24:02d}:{round(h % 1 * 60) % 60:02d}"))
    ax_k.set_title(f"{len(folders)} folder(s): k and rho against time of day")
    for ax in (ax_k, ax_rho):
        ax.grid(True, alpha=0.3)
    if len(folders) <= 12:  # beyond that a legend hides the data
        ax_k.legend(fontsize="small", ncols=2 if len(folders) > 6 else 1)
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=_DPI)
    return path
