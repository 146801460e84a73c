"""One-sigma errors of k and rho that include the model's systematic error (NumPy only).

The fit's classic error (``solve.covariance``: the Jacobian at the solution and the
residual variance) assumes independent residuals and a model that is exactly right. On
photos neither holds: residuals along one stretch of shadow edge share texture, JPEG
blocks and the model's misfit, and the model's profile, blur, hidden sky,
interreflection and finite resolution bias k and rho by more than the noise does
(``softshadow demo`` read k 8 % high at 7.5 of its classic errors). Two terms are added:

- **statistical, cluster-robust**: a sandwich covariance whose "meat" sums the score
  J_c^T r_c of whole stretches of edge (clusters of neighbouring profiles), so that
  residuals correlated along the edge count once per stretch, not once per pixel. The
  statistical error is the larger of it and the classic one.
- **systematic**: a floor calibrated on independent physics (``data_synth``'s physical
  renderer, held-out seeds; ``examples/coverage_study.py --calibrate``), relative for k
  and growing as the penumbra narrows towards the pixel size (blur and profile shape
  then decide k), and absolute plus relative for rho.

Both are added in quadrature. docs/uncertainty.md has the calibration and the coverage
measured on folders not used for it.

Without geometry (one photo, ``edge_measure``) the statistical part is the block
bootstrap of the median profile rho, and the systematic part (``EdgeFloor``) is relative
to rho (the hidden sky, umbrae on other ground, albedo edges bias the median by more than
its bootstrap says), with a term for the spread of the kept profiles' rho that the
calibration on ``street`` renders set to zero: there the spread did not foretell the
error (``examples/street_table.py --calibrate``).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

__all__ = ["SystematicFloor", "CALIBRATED_FLOOR", "LOD_FLOOR", "Uncertainty", "edge_clusters", "cluster_covariance",
           "systematic_errors", "combine_errors", "CLUSTERS_PER_PHOTO", "EdgeFloor", "CALIBRATED_EDGE_FLOOR",
           "profile_spread", "edge_rho_errors"]

#: Stretches of edge per photo for the cluster-robust covariance: few enough that one
#: stretch spans the residuals' correlation along the edge, enough for a stable sum.
CLUSTERS_PER_PHOTO = 8


class SystematicFloor(NamedTuple):
    """The systematic one-sigma error model (physical units).

    sigma_k_sys / k = sqrt(k_rel^2 + (k_rel_px / penumbra_px)^2): a relative floor, and a
    part that grows as the penumbra (image pixels, median over the fit's samples) narrows.
    sigma_rho_sys = sqrt(rho_abs^2 + (rho_rel rho)^2).
    """

    k_rel: float
    k_rel_px: float
    rho_abs: float
    rho_rel: float


#: Calibrated on the randomized calibration study (``softshadow bench --what coverage``, seed 0, 300
#: groups): the smallest floor on a grid (k_rel 0.15-0.23, k_rel_px 0.06-0.15, rho_abs 0.002-0.004,
#: rho_rel 0.02-0.04) under which the truth lay within 2 stated sigma for at least 90 % of k and of
#: rho among the reliable groups in every bin of every factor, on each half of the study (even and
#: odd indices, bins of 10 or more reliable groups) and on the whole (bins of 20 or more). A floor
#: set for 95 % overall (0.15, 0.06, 0.002, 0.02) covered 94-95 % overall but 85-89 % in five bins
#: (the knot, two photos, a sun of 8-20 deg, k 0.004-0.008, the sun from time and site).
CALIBRATED_FLOOR = SystematicFloor(k_rel=0.21, k_rel_px=0.06, rho_abs=0.003, rho_rel=0.03)
#: The floor that the level-of-detail tolerance (``fitting.solve.lod``: a level moves k and rho by at
#: most so many stated errors) was measured with: the levels chosen stay those measured.
LOD_FLOOR = SystematicFloor(k_rel=0.08, k_rel_px=0.0, rho_abs=0.002, rho_rel=0.0)


class Uncertainty(NamedTuple):
    """One-sigma errors of k and rho: total (stated), statistical and systematic parts."""

    range_stderr: float
    rho_stderr: float
    range_stderr_stat: float
    rho_stderr_stat: float
    range_stderr_sys: float
    rho_stderr_sys: float


def edge_clusters(profile_ids: list[np.ndarray], n_rows: int,
                  per_photo: int = CLUSTERS_PER_PHOTO) -> np.ndarray:
    """Cluster index (n_rows,) of each residual row: each photo's profiles (``profile_ids``,
    one (n_i,) array per photo, in row order; ids number the profiles along the edge) are cut
    into ``per_photo`` runs of neighbouring ids. Rows beyond the photos (padding) get -1."""
    out = np.full(n_rows, -1, dtype=np.int64)
    start, base = 0, 0
    for ids in profile_ids:
        ids = np.asarray(ids)
        n = len(ids)
        if n:
            uniq, inverse = np.unique(ids, return_inverse=True)
            blocks = min(per_photo, len(uniq))
            out[start:start + n] = base + (inverse * blocks) // len(uniq)
            base += blocks
        start += n
    return out


def cluster_covariance(r: np.ndarray, jac: np.ndarray, clusters: np.ndarray, rcond: float = 1e-6) -> np.ndarray:
    """Cluster-robust (sandwich) covariance (p, p) of the parameters: B^+ M B^+ G / (G - 1),
    with B = J^T J (through the SVD of J (n, p): singular values below ``rcond`` of the largest
    count as zero, as in ``solve.covariance``), M = sum over clusters c of g_c g_c^T,
    g_c = J_c^T r_c, and G the number of clusters. Rows with cluster -1 are left out."""
    use = clusters >= 0
    r, jac, clusters = np.asarray(r)[use], np.asarray(jac)[use], np.asarray(clusters)[use]
    p = jac.shape[1]
    ids, inverse = np.unique(clusters, return_inverse=True)
    g = len(ids)
    if g < 2:
        return np.full((p, p), np.nan)
    scores = np.zeros((g, p))
    np.add.at(scores, inverse, jac * r[:, None])
    _, sv, vt = np.linalg.svd(jac, full_matrices=False)
    keep = sv > rcond * (sv[0] if len(sv) else 0.0)
    inv_sq = np.where(keep, 1.0 / np.where(keep, sv, 1.0) ** 2, 0.0)
    bread = (vt.T * inv_sq) @ vt
    meat = scores.T @ scores
    return bread @ meat @ bread * (g / (g - 1.0))


def systematic_errors(k: float, rho: float, penumbra_px: float | None,
                      floor: SystematicFloor = CALIBRATED_FLOOR) -> tuple[float, float]:
    """The systematic one-sigma errors (of k, of rho) of ``floor`` at a fitted k, rho and
    penumbra width in pixels (None or below 0.5 px counts as 0.5 px: the resolution then
    decides k, which the rule book, ``fitting.verdict.rules``, reports as an upper bound anyway)."""
    px = max(float(penumbra_px), 0.5) if penumbra_px else 0.5
    k_rel = float(np.hypot(floor.k_rel, floor.k_rel_px / px))
    return abs(float(k)) * k_rel, float(np.hypot(floor.rho_abs, floor.rho_rel * float(rho)))


def combine_errors(k: float, rho: float, classic: tuple[float, float], robust: tuple[float, float],
                   penumbra_px: float | None, floor: SystematicFloor = CALIBRATED_FLOOR) -> Uncertainty:
    """Stated errors: the statistical part is the larger of the classic and the cluster-robust
    errors (either may be NaN: the other is used), the systematic part ``systematic_errors``;
    the two in quadrature."""
    def stat(a, b):
        vals = [v for v in (a, b) if v is not None and np.isfinite(v)]
        return float(max(vals)) if vals else float("nan")

    sk, sr = stat(classic[0], robust[0]), stat(classic[1], robust[1])
    yk, yr = systematic_errors(k, rho, penumbra_px, floor)
    return Uncertainty(float(np.hypot(sk, yk)), float(np.hypot(sr, yr)), sk, sr, yk, yr)


class EdgeFloor(NamedTuple):
    """The systematic one-sigma error of rho measured without geometry (one photo's edges).

    sigma_rho_sys = sqrt(rho_abs^2 + (rho_rel rho)^2 + (rho_spread rho s)^2), with s the
    robust spread (``profile_spread``) of the kept profiles' log rho.
    """

    rho_abs: float
    rho_rel: float
    rho_spread: float


#: Calibrated on street renders (seeds 100-129; docs/uncertainty.md "Without
#: geometry": the coverage seeds 0-11 are never used for it).
CALIBRATED_EDGE_FLOOR = EdgeFloor(rho_abs=0.0, rho_rel=0.11, rho_spread=0.0)


def profile_spread(log_rho: np.ndarray) -> float:
    """Robust standard deviation (normal-scaled median absolute deviation) of the profiles'
    log rho (n,); 0 for fewer than two profiles."""
    from scipy.stats import median_abs_deviation

    log_rho = np.asarray(log_rho, dtype=float)
    log_rho = log_rho[np.isfinite(log_rho)]
    return float(median_abs_deviation(log_rho, scale="normal")) if len(log_rho) > 1 else 0.0


def edge_rho_errors(rho: float, stat: float, spread: float,
                    floor: EdgeFloor = CALIBRATED_EDGE_FLOOR) -> Uncertainty:
    """Stated errors of a rho measured without geometry: the statistical part ``stat`` (the
    bootstrap error; NaN stays NaN) and the systematic part of ``floor`` at ``rho`` and the
    profiles' log-rho spread ``spread``, in quadrature. There is no k: its fields are NaN."""
    _, base = systematic_errors(0.0, rho, None, SystematicFloor(0.0, 0.0, floor.rho_abs, floor.rho_rel))
    sys = float(np.hypot(base, floor.rho_spread * abs(float(rho)) * float(spread)))
    nan = float("nan")
    return Uncertainty(nan, float(np.hypot(float(stat), sys)), nan, float(stat), nan, sys)
