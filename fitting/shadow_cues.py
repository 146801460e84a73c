"""What is true of cast shadows, as checks on the profiles of a single photo (NumPy/SciPy).

Used by ``fitting.edge_measure`` after the per-profile tests:

- ``bluer_umbrae``: under a blue sky the umbra is lit by the sky alone and is
  bluer than the sunlit ground beside it; paint, kerbs and material borders
  are not. When enough profiles show that, the ones that do not are not cast
  shadows.
- ``log_rho_modes``: one sun and one sky give every shadow edge on the ground
  the same step; several well-filled modes of log rho mean the edges disagree.
- ``edge_structures``: profiles that lie along one outline are one piece of
  evidence, not many; a few profiles scattered over unrelated structures are
  weak evidence whatever their spread.
- ``reliability``: the warnings (one line each) and the ``reliable`` flag
  derived from the above.
"""

from __future__ import annotations

import numpy as np
from scipy import stats
from scipy.cluster.hierarchy import fcluster, linkage
from scipy.signal import find_peaks

__all__ = ["bluer_umbrae", "log_rho_modes", "edge_structures", "reliability", "mode_of_log_rho",
           "disagreement_warning", "few_profiles_warning"]

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
# A second mode holding this share of the first's members (and at least
# SECOND_MODE_MIN profiles): the edges disagree. On DSC_0569 the second mode
# held 11 profiles against 105 (paint); on the street preset a kerb's mode
# held 40 against the shadows' 43, and on other seeds the shadows' mode was
# the smaller one.
SECOND_MODE_SHARE = 0.25
SECOND_MODE_MIN = 8
RELIABLE_MIN_PROFILES = 10     # fewer kept profiles than this: too little evidence
STRUCTURE_LINK = 0.04          # profiles closer than this fraction of the image diagonal: one structure
PROFILES_PER_STRUCTURE = 5     # more structures than kept / this (and than 2): scattered evidence


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


def few_profiles_warning(n_profiles: int) -> str | None:
    """The warning for a measurement that rests on fewer than RELIABLE_MIN_PROFILES profiles
    (with or without geometry), or None."""
    return f"only {n_profiles} shadow-edge profiles" if n_profiles < RELIABLE_MIN_PROFILES else None


def disagreement_warning(modes: list[tuple[float, int]], measured_log: float) -> str:
    """The one "edges disagree" warning: the mode the reported rho comes from (the highest
    density, ``mode_of_log_rho``: ``measured_log``) named first as "measured", then the fullest
    other mode. Modes are (log peak, profiles) as ``log_rho_modes`` gives them, two or more.
    Named this way, the warning, the table's value and results.json's rho always agree on
    which mode was measured (ordering by profile count alone named the other one first when
    the denser mode held fewer profiles)."""
    i = int(np.argmin([abs(peak - measured_log) for peak, _ in modes]))
    other = next(m for j, m in enumerate(modes) if j != i)
    return (f"edges disagree: measured rho {np.exp(modes[i][0]):.3f} ({modes[i][1]} profiles), "
            f"another mode at rho {np.exp(other[0]):.3f} ({other[1]} profiles)")


def reliability(shadow_like_log_rho: np.ndarray, kept_positions_uv: np.ndarray, image_shape: tuple[int, int],
                lowest_log: float) -> tuple[list[str], bool]:
    """(warnings, reliable) of a single-photo measurement.

    shadow_like_log_rho: (M,) log rho of every profile that passed the
        per-profile tests (before the dominant mode was chosen).
    kept_positions_uv: (N,) positions of the profiles the result rests on.
    """
    warnings: list[str] = []
    modes = log_rho_modes(shadow_like_log_rho, lowest_log)
    if len(modes) > 1 and modes[1][1] >= max(SECOND_MODE_SHARE * modes[0][1], SECOND_MODE_MIN):
        warnings.append(disagreement_warning(modes, mode_of_log_rho(shadow_like_log_rho, lowest_log)))
    n = int(np.asarray(kept_positions_uv).reshape(-1, 2).shape[0])
    if few_profiles_warning(n):
        warnings.append(few_profiles_warning(n))
    if n:
        n_struct = int(np.unique(edge_structures(kept_positions_uv, image_shape)).size)
        if n_struct > max(2, n / PROFILES_PER_STRUCTURE):
            warnings.append(f"{n} profiles spread over {n_struct} separate structures")
    return warnings, not warnings
