"""What is true of cast shadows, as checks on the profiles of a single photo (NumPy/SciPy).

Used by ``fitting.edges.measure`` after the per-profile tests:

- ``bluer_umbrae``: under a blue sky the umbra is lit by the sky alone and is
  bluer than the sunlit ground beside it; paint, kerbs and material borders
  are not. When enough profiles show that, the ones that do not are not cast
  shadows.
- ``log_rho_modes``: one sun and one sky give every shadow edge on the ground
  the same step; several well-filled modes of log rho mean the edges disagree.
- ``edge_structures``: profiles that lie along one outline are one piece of
  evidence, not many; a few profiles scattered over unrelated structures are
  weak evidence whatever their spread.
- ``textured_outlines``: a shadow leaves the ground's fine texture alone;
  an outline whose dark side is, over its whole length, much rougher (or
  smoother) than its lit side is a border between two materials.
- ``outline_disagreement``: one shadow has one step all along its outline,
  and all shadows on the ground share it; separate outlines whose medians
  differ are not all cast shadows.
- ``dark_side_regions`` / ``scattered_dark_sides``: the dark side of a cast
  shadow is one connected region; the dark sides of a shadow's profiles all
  fall in it, while edges picked up on unrelated dark things (gaps, stains,
  dark stones, facade details) each have a dark blob of their own.
- ``edge_evidence``: the above for the profiles a measurement rests on, as the
  typed evidence the rule book judges (``fitting.verdict.edge_rules``: the
  warnings and the ``reliable`` flag are decided there).
"""

from __future__ import annotations

import numpy as np
from scipy import ndimage, stats
from scipy.cluster.hierarchy import fcluster, linkage
from scipy.signal import find_peaks

from ..verdict.evidence import EdgeEvidence

__all__ = ["bluer_umbrae", "log_rho_modes", "edge_structures", "mode_of_log_rho", "textured_outlines",
           "dark_side_regions", "outlines", "edge_evidence"]

# Skylit umbrae are bluer: on the real photo DSC_0569 the blue step minus the
# red step was about 0.8 (log) across shadow edges, about 0 across paint; the
# tints of grey materials (asphalt against concrete) give up to 0.15.
BLUER_MIN_LOG = 0.25
# The blue cue is used only when at least this many profiles (and this share
# of the shadow-like ones) show it, i.e. when the sky is blue at all.
BLUER_MIN_COUNT = 5
BLUER_MIN_SHARE = 0.2
MODE_BANDWIDTH_LOG = 0.05      # kernel density bandwidth of log rho
MODE_WINDOW_LOG = 0.25         # a mode's members lie within this of its peak (farther: other edges)
# A shadow does not change the fine texture of the ground: along a shadow
# outline the dark/lit ratio of the high-pass log texture stays near 1, or
# grows to 1 / sqrt(rho) where shot noise dominates a smooth surface (the
# darker side is noisier). So the ratio times sqrt(rho) is compared: its
# median over an outline was 0.18-0.87 on the shadows of the street preset,
# DSC_0569 and p21_1, and 1.56-1.78 across the street preset's kerbs (smooth
# concrete against asphalt; per profile 1.7-7 before the sqrt(rho)). An
# outline of at least OUTLINE_TEXTURE_MIN_PROFILES measured profiles whose
# median is above this is two materials, not a shadow.
OUTLINE_TEXTURE_MAX = 1.35
OUTLINE_TEXTURE_MIN_PROFILES = 3
# The dark-side cue. The working log image is smoothed (Gaussian, this sigma in
# working pixels, masked pixels left out) so that texture does not cut a
# shadow into pieces, thresholded halfway (in log) between the kept profiles'
# median umbra and lit levels, and labelled (8-connected). A profile's dark
# side is sampled DARK_SIDE_STEP_PX beyond its ramp's dark end.
DARK_SMOOTH_PX = 1.5
DARK_SIDE_STEP_PX = 2.0
STRUCTURE_LINK = 0.04          # profiles closer than this fraction of the image diagonal: one structure


def bluer_umbrae(blue_shift_log: np.ndarray) -> np.ndarray | None:
    """(N,) bool of the profiles whose dark side is bluer, or None when the cue does not apply.

    blue_shift_log: (N,) log step of blue minus that of red (NaN: no colour).
    None when too few profiles are bluer (an overcast or gray sky, a gray image).
    """
    b = np.asarray(blue_shift_log, float)
    bluer = np.isfinite(b) & (b > BLUER_MIN_LOG)
    if bluer.sum() < BLUER_MIN_COUNT or bluer.sum() < BLUER_MIN_SHARE * b.size:
        return None
    return bluer


def _density(log_rho: np.ndarray, grid: np.ndarray) -> np.ndarray:
    """Gaussian kernel density of log rho on grid with the fixed bandwidth MODE_BANDWIDTH_LOG."""
    spread = float(np.std(log_rho))
    if log_rho.size < 2 or spread < 1e-9:
        return np.exp(-0.5 * ((grid - np.mean(log_rho)) / MODE_BANDWIDTH_LOG) ** 2)
    # gaussian_kde scales a scalar bandwidth by the data's std: divide it out for a fixed width.
    return stats.gaussian_kde(log_rho, bw_method=MODE_BANDWIDTH_LOG / spread)(grid)


def mode_of_log_rho(log_rho: np.ndarray, lowest_log: float) -> float:
    """The highest-density log rho on a grid from lowest_log to 0 (0.005 steps)."""
    grid = np.arange(lowest_log, 0.0, 0.005)
    return float(grid[int(np.argmax(_density(np.asarray(log_rho, float), grid)))])


def log_rho_modes(log_rho: np.ndarray, lowest_log: float) -> list[tuple[float, int]]:
    """Separate modes of log rho as (peak, members), most members first.

    A mode's members lie within MODE_WINDOW_LOG of its peak; peaks closer
    than that to a fuller mode are the same mode.
    """
    x = np.asarray(log_rho, float)
    if x.size == 0:
        return []
    grid = np.arange(lowest_log, 0.0, 0.005)
    dens = _density(x, grid)
    peaks, _ = find_peaks(np.concatenate([[0.0], dens, [0.0]]))
    peaks = peaks - 1
    modes = sorted(((float(grid[p]), int(np.sum(np.abs(x - grid[p]) <= MODE_WINDOW_LOG))) for p in peaks),
                   key=lambda m: -m[1])
    out: list[tuple[float, int]] = []
    for peak, n in modes:
        if all(abs(peak - q) > MODE_WINDOW_LOG for q, _ in out):
            out.append((peak, n))
    return out


def edge_structures(positions_uv: np.ndarray, image_shape: tuple[int, int]) -> np.ndarray:
    """(N,) labels grouping profile positions (px) into structures (single linkage, STRUCTURE_LINK x diagonal)."""
    pts = np.asarray(positions_uv, float).reshape(-1, 2)
    if pts.shape[0] < 2:
        return np.ones(pts.shape[0], int)
    link = STRUCTURE_LINK * float(np.hypot(*image_shape))
    return fcluster(linkage(pts, method="single"), t=link, criterion="distance")


def textured_outlines(texture_ratio: np.ndarray, rho: np.ndarray, labels: np.ndarray) -> np.ndarray:
    """(N,) bool: the profiles on outlines whose median texture ratio (dark/lit) times sqrt(rho) exceeds
    OUTLINE_TEXTURE_MAX.

    texture_ratio: (N,) per profile (NaN: not measured, e.g. both sides smooth);
    rho: (N,) their steps; labels: (N,) their outlines (``edge_structures``).
    Outlines with fewer than OUTLINE_TEXTURE_MIN_PROFILES measured ratios are not judged.
    """
    r = np.asarray(texture_ratio, float) * np.sqrt(np.asarray(rho, float))
    out = np.zeros(r.size, bool)
    for k in np.unique(labels):
        member = labels == k
        measured = r[member & np.isfinite(r)]
        if measured.size >= OUTLINE_TEXTURE_MIN_PROFILES and np.median(measured) > OUTLINE_TEXTURE_MAX:
            out |= member
    return out


def dark_side_regions(log_image: np.ndarray, valid: np.ndarray, dark_uv: np.ndarray,
                      threshold_log: float) -> np.ndarray:
    """(N,) label of the connected dark region each profile's dark side lies in (0: not in a dark region).

    log_image: (H, W) log of the (working-scale) photo; valid: (H, W) bool, False = masked or clipped.
    dark_uv: (N, 2) pixel (u, v) of each profile's dark-side sample.
    threshold_log: pixels of the smoothed log image below this are dark (halfway between umbra and lit).
    Regions are 8-connected components of the dark valid pixels (``scipy.ndimage.label``). A sample that
    is not itself dark (texture, a pixel off the ramp's end) takes the label most of its 5x5 neighbours have.
    """
    log = np.asarray(log_image, float)
    ok = np.asarray(valid, bool) & np.isfinite(log)
    w = ndimage.gaussian_filter(ok.astype(float), DARK_SMOOTH_PX)
    smooth = ndimage.gaussian_filter(np.where(ok, log, 0.0), DARK_SMOOTH_PX) / np.maximum(w, 1e-12)
    labels, _ = ndimage.label(ok & (smooth < threshold_log), structure=np.ones((3, 3), int))
    uv = np.rint(np.asarray(dark_uv, float).reshape(-1, 2)).astype(int)
    h, wd = labels.shape
    out = np.zeros(uv.shape[0], int)
    for i, (u, v) in enumerate(uv):
        if not (0 <= u < wd and 0 <= v < h):
            continue
        if labels[v, u]:
            out[i] = labels[v, u]
            continue
        near = labels[max(v - 2, 0):v + 3, max(u - 2, 0):u + 3].ravel()
        near = near[near > 0]
        if near.size:
            out[i] = int(np.bincount(near).argmax())
    return out


def outlines(log_rho: np.ndarray, labels: np.ndarray) -> tuple[tuple[float, int], ...]:
    """(median log rho, profiles) of each outline: log_rho (N,) of the kept profiles, labels (N,) their
    structures (``edge_structures``)."""
    x = np.asarray(log_rho, float)
    return tuple((float(np.median(x[labels == k])), int(np.sum(labels == k))) for k in np.unique(labels))


def edge_evidence(shadow_like_log_rho: np.ndarray, kept_positions_uv: np.ndarray, image_shape: tuple[int, int],
                  lowest_log: float, kept_log_rho: np.ndarray, dark_region_labels: np.ndarray | None) -> EdgeEvidence:
    """The cues of a single-photo measurement, for the rule book (``fitting.verdict.edge_rules``).

    shadow_like_log_rho: (M,) log rho of every profile that passed the per-profile tests (before the
        dominant mode was chosen).
    kept_positions_uv: (N, 2) positions of the profiles the result rests on; kept_log_rho: (N,) their
        log rho. dark_region_labels: (N,) ``dark_side_regions`` of their dark sides (None: not found).
    """
    modes = tuple(log_rho_modes(shadow_like_log_rho, lowest_log))
    measured = mode_of_log_rho(shadow_like_log_rho, lowest_log) if len(shadow_like_log_rho) else float("nan")
    positions = np.asarray(kept_positions_uv).reshape(-1, 2)
    labels = edge_structures(positions, image_shape) if len(positions) else np.zeros(0, int)
    dark = ()
    if dark_region_labels is not None:
        lab = np.asarray(dark_region_labels, int)
        dark = tuple(int(c) for c in np.unique(lab[lab > 0], return_counts=True)[1])
    return EdgeEvidence(modes=modes, measured_log=float(measured), n_kept=int(len(positions)),
                        n_structures=int(np.unique(labels).size), outlines=outlines(kept_log_rho, labels),
                        dark_side_regions=dark)
