"""The evidence a fitted group hands the rule book (NumPy, after the solve): each photo's residuals
per region, its noise, its misfit and its own estimate of k and rho (``fitting.verdict.evidence``).

Regions. A sample is on the lit ground when the fitted shadow leaves it lit (alpha below
``_LIT_ALPHA``) and it lies more than ``REGION_MARGIN_PX`` beyond the penumbra (u > 1, by its own
fitted |du/dpixel|); in the umbra when alpha is at least ``_UMBRA_ALPHA`` and it lies as far inside
(u < -1); inside the penumbra when |u| < 1. The margin keeps the camera's blur and a shadow a pixel
off out of the noise estimates.

Noise. The normal-scaled median absolute deviation of the residuals on the lit ground and in the
umbra: the photo's noise and the ground's texture, which the model does not describe, robust to the
few samples a misplaced edge puts on the wrong side.

A photo's own estimate. The group's fit is moved to one photo's samples by one Gauss-Newton step
from the group's solution, in the parameters those samples depend on (k, rho, the sun's correction
when it is fitted, and the photo's own blur, levels and brightness gradient); its statistical error
is the classic one of that step, scaled as the group's statistical error is scaled over its classic
error (the residuals' correlation along the edge, ``fitting.solve.uncertainty``).
"""

from __future__ import annotations

import dataclasses

import numpy as np

from ..samples.receiver_light import shadow_factor
from ..verdict.evidence import NAN, PhotoEvidence
from .model import K_SCALE, FitParams, Prediction

__all__ = ["REGION_MARGIN_PX", "photo_evidence", "photo_estimates", "photos_evidence", "no_ramp_k",
           "penumbra_px_per_k", "remaining_step_se"]

#: A sample counts for the lit ground's or the umbra's noise when it lies this many pixels beyond
#: the fitted penumbra: the camera's blur (0.5-0.9 px on the synthetic cameras) and a penumbra a
#: pixel off then leave it alone.
REGION_MARGIN_PX = 2.0
_LIT_ALPHA, _UMBRA_ALPHA = 0.01, 0.99  # the fitted shadow leaves a sample lit / puts it in the umbra
_MIN_NOISE_SAMPLES = 20  # fewer samples than this in a region: its noise is not measured
_MIN_DEPTH_SAMPLES = 10  # samples needed on each side to measure a shadow's depth
_MISFIT_KEPT = 0.9  # the share of samples (the smallest ratios) the misfit is taken over
_COV_RCOND = 1e-6


def _robust_spread(x: np.ndarray) -> float:
    if len(x) < _MIN_NOISE_SAMPLES:
        return NAN
    return float(1.4826 * np.median(np.abs(x - np.median(x))))


def _rms(x: np.ndarray) -> float:
    return float(np.sqrt(np.mean(x ** 2))) if len(x) else NAN


def _median(x: np.ndarray, need: int) -> float:
    return float(np.median(x)) if len(x) >= need else NAN


def photo_evidence(name: str, observed: np.ndarray, prediction: Prediction, rho: float,
                   sun_cos: np.ndarray, sky_hidden: np.ndarray) -> PhotoEvidence:
    """One photo's residuals, regions, noise and misfit (``PhotoEvidence`` without its own estimate).

    observed (n,): the samples' linear values; prediction: the fitted model at those samples (its
    fields (n,) each); rho: the fitted rho; sun_cos, sky_hidden (n,): the samples' sun incidence
    and hidden sky (``fitting.samples.receiver_light``)."""
    values, alpha, u, slope = (np.asarray(a, dtype=np.float64) for a in prediction)
    level = values / np.maximum(shadow_factor(alpha, rho, sun_cos, 1.0 - sky_hidden), 1e-9)
    level = np.where(np.isfinite(level) & (level > 0), level, np.nan)
    obs, fit = observed / level, values / level
    r = obs - fit
    ok = np.isfinite(r)
    # Pixels beyond the penumbra, by the samples' own fitted |du/dpixel| (0 beyond the planned bands:
    # infinitely far).
    with np.errstate(divide="ignore", invalid="ignore"):
        beyond = np.where(slope > 0, (np.abs(u) - 1.0) / slope, np.inf)
    outside, inside_umbra = ok & (u > 1) & (beyond > REGION_MARGIN_PX), ok & (u < -1) & (beyond > REGION_MARGIN_PX)
    lit, umbra = outside & (alpha < _LIT_ALPHA), inside_umbra & (alpha >= _UMBRA_ALPHA)
    inside = ok & (np.abs(u) < 1)
    noise_lit, noise_umbra = _robust_spread(r[lit]), _robust_spread(r[umbra])
    # Without a measured umbra noise, the lit ground's scaled as shot noise (the larger of texture,
    # which scales with the level, and shot noise): the misfit errs on the low side.
    sigma_lit = noise_lit if np.isfinite(noise_lit) else noise_umbra / np.sqrt(max(rho, 0.01))
    sigma_umbra = noise_umbra if np.isfinite(noise_umbra) else noise_lit * np.sqrt(max(rho, 0.01))
    misfit = NAN
    if np.isfinite(sigma_lit) and np.isfinite(sigma_umbra) and ok.any():
        a = np.clip(alpha[ok], 0.0, 1.0)
        sigma = np.maximum(sigma_lit * (1 - a) + sigma_umbra * a, 1e-9)
        z = np.sort(np.abs(r[ok]) / sigma)
        misfit = _rms(z[:max(int(_MISFIT_KEPT * len(z)), 1)])
    # The depth where the shadow's geometry puts the lit ground and the umbra, whatever the photo's
    # fitted blur: a frame without the shadow is fitted with a blur that flattens the model's shadow,
    # and then has no sample whose alpha reaches the umbra.
    depth = _median(obs[outside], _MIN_DEPTH_SAMPLES) - _median(obs[inside_umbra], _MIN_DEPTH_SAMPLES)
    predicted = _median(fit[outside], _MIN_DEPTH_SAMPLES) - _median(fit[inside_umbra], _MIN_DEPTH_SAMPLES)
    gap = _median(r[outside], _MIN_DEPTH_SAMPLES) - _median(r[inside_umbra], _MIN_DEPTH_SAMPLES)
    return PhotoEvidence(
        photo=name, n_samples=int(ok.sum()), n_lit=int(lit.sum()), n_umbra=int(umbra.sum()),
        n_penumbra=int(inside.sum()), rms=_rms(r[ok]), rms_lit=_rms(r[lit]), rms_umbra=_rms(r[umbra]),
        rms_penumbra=_rms(r[inside]), noise_lit=noise_lit, noise_umbra=noise_umbra,
        misfit=misfit, shadow_depth=depth, predicted_depth=predicted, depth_gap=gap)


def photo_estimates(params: FitParams, residuals: np.ndarray, jacobian: np.ndarray, photo_rows: list[slice], *,
                    fit_sun: bool, fit_blur: bool, stat_scale: tuple[float, float]
                    ) -> list[tuple[float, float, float, float]]:
    """Each photo's own (k, k_stderr, rho, rho_stderr): one Gauss-Newton step from the group's
    solution ``params`` on that photo's rows of the residuals (n,) and their Jacobian (n, p)
    (``FitParams.layout`` columns), in k, rho, the sun's correction (``fit_sun``), and the photo's
    blur (``fit_blur``), levels and gradient. The errors are the step's classic errors times
    ``stat_scale`` (the group's statistical over its classic error, for k and for rho)."""
    n_photos = params.n_photos
    lay = FitParams.layout(n_photos)
    raw_k, raw_rho = float(params.raw_k), float(params.raw_rho)
    out = []
    for p, rows in enumerate(photo_rows):
        cols = [lay["raw_k"].start, lay["raw_rho"].start]
        if fit_sun:
            cols += list(range(lay["sun_delta_deg"].start, lay["sun_delta_deg"].stop))
        if fit_blur:
            cols.append(lay["raw_blur"].start + p)
        cols += [lay["log_level"].start + 2 * p + c for c in (0, 1)]
        cols += [lay["gradient"].start + 2 * p + c for c in (0, 1)]
        j, r = np.asarray(jacobian)[rows][:, cols], np.asarray(residuals)[rows]
        if len(r) <= len(cols):
            out.append((NAN, NAN, NAN, NAN))
            continue
        step, cov = _gauss_newton_step(j, r)
        k, rho, dk = _k_rho_after(raw_k + step[0], raw_rho + step[1])
        se_k = float(np.sqrt(max(cov[0, 0], 0.0)) * dk * stat_scale[0])
        se_rho = float(np.sqrt(max(cov[1, 1], 0.0)) * rho * (1 - rho) * stat_scale[1])
        out.append((k, se_k, rho, se_rho))
    return out


def _gauss_newton_step(j: np.ndarray, r: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The Gauss-Newton step (p,) that the residuals r (n,) and their Jacobian j (n, p) ask for,
    and its classic covariance (p, p) (directions with singular values below _COV_RCOND of the
    largest, such as switched-off terms' zero columns, are left alone)."""
    left, sv, vt = np.linalg.svd(j, full_matrices=False)
    keep = sv > _COV_RCOND * (sv[0] if len(sv) else 0.0)
    inv = np.where(keep, 1.0 / np.where(keep, sv, 1.0), 0.0)
    step = -(vt.T * inv) @ (left.T @ r)
    dof = max(len(r) - int(keep.sum()), 1)
    r_after = r + j @ step
    return step, (vt.T * inv ** 2) @ vt * (float(r_after @ r_after) / dof)


def _k_rho_after(raw_k: float, raw_rho: float) -> tuple[float, float, float]:
    """k, rho and dk/draw_k at these raw parameters (``fitting.solve.model``), in NumPy."""
    k = K_SCALE * float(np.logaddexp(0.0, raw_k))
    rho = float(np.exp(-np.logaddexp(0.0, -raw_rho)))  # sigmoid, without overflow
    return k, rho, K_SCALE * float(np.exp(-np.logaddexp(0.0, -raw_k)))


def remaining_step_se(params: FitParams, residuals: np.ndarray, jacobian: np.ndarray, k_stderr: float,
                      rho_stderr: float) -> float:
    """How far one more Gauss-Newton step from the solution ``params`` would still move k or rho, in
    units of their errors ``k_stderr`` and ``rho_stderr`` (the larger of the two; NaN when the
    residuals (n,) or their Jacobian (n, p) are not finite, or an error is not positive)."""
    r, j = np.asarray(residuals, dtype=np.float64), np.asarray(jacobian, dtype=np.float64)
    if not (np.isfinite(r).all() and np.isfinite(j).all() and k_stderr > 0 and rho_stderr > 0):
        return NAN
    lay = FitParams.layout(params.n_photos)
    step, _ = _gauss_newton_step(j, r)
    raw_k, raw_rho = float(params.raw_k), float(params.raw_rho)
    k0, rho0, _ = _k_rho_after(raw_k, raw_rho)
    k1, rho1, _ = _k_rho_after(raw_k + step[lay["raw_k"].start], raw_rho + step[lay["raw_rho"].start])
    return max(abs(k1 - k0) / k_stderr, abs(rho1 - rho0) / rho_stderr)


def photos_evidence(samples, rows: list[slice], solution, est, errors, sun_cos: np.ndarray, sky_hidden: np.ndarray,
                    *, fit_sun: bool, fit_blur: bool) -> list[PhotoEvidence]:
    """Every photo's ``PhotoEvidence`` with its own estimate, from a group's solution.

    samples: the photos' ``PhotoSamples``; rows: their rows in the group's arrays; solution: the
    ``fitting.solve.group.Solution``; est: its k and rho with their classic errors (``KRho``);
    errors: the stated errors (``fitting.solve.uncertainty.Uncertainty``); sun_cos, sky_hidden (n,)."""
    scale = (errors.range_stderr_stat / max(est.range_stderr, 1e-300),
             errors.rho_stderr_stat / max(est.rho_stderr, 1e-300))
    own = photo_estimates(solution.params, solution.residuals, solution.jacobian, rows, fit_sun=fit_sun,
                          fit_blur=fit_blur, stat_scale=scale)
    out = []
    for s, sl, (k, k_se, rho, rho_se) in zip(samples, rows, own):
        prediction = Prediction(*(np.asarray(a)[sl] for a in solution.prediction))
        e = photo_evidence(s.name, s.observed, prediction, est.rho, sun_cos[sl], sky_hidden[sl])
        out.append(dataclasses.replace(e, k=k, k_stderr=k_se, rho=rho, rho_stderr=rho_se))
    return out


#: The share of the samples nearest the shadow's outline (smallest |u|) over which the penumbra's
#: width per unit k is taken: the outline's own geometry, away from the far ends of the bands.
_NEAREST_SHARE = 0.1


def penumbra_px_per_k(u: np.ndarray, slope: np.ndarray, k: float) -> float | None:
    """The penumbra's width in image pixels per unit k, the median over the samples nearest the
    outline: the width 2 / |du/dpixel| grows in proportion to k, so width / k is the outline's
    geometry and tells the width any k would have, even when the fitted k leaves no sample inside
    the penumbra. u, slope (n,) without padding; None when no sample lies within the planned bands."""
    u = np.abs(np.asarray(u, dtype=np.float64))
    slope = np.asarray(slope, dtype=np.float64)
    keep = (u < 1e5) & np.isfinite(slope) & (slope > 0)
    if not keep.any() or not k > 0:
        return None
    u, slope = u[keep], slope[keep]
    nearest = u <= np.quantile(u, _NEAREST_SHARE)
    return float(np.median(2.0 / (slope[nearest] * k)))


def no_ramp_k(u: np.ndarray, k: float) -> float | None:
    """When no sample lies inside the fitted penumbra (|u| >= 1 everywhere), the largest k the samples
    allow: the penumbra's half-width grows in proportion to k, so the penumbra of k * min |u| would
    just reach the nearest sample, which shows no ramp. None when some sample lies inside, or every
    sample lies beyond the planned bands (u = +-1e6: no bound from them). u (n,) without padding."""
    u = np.abs(np.asarray(u, dtype=np.float64))
    u = u[u < 1e5]
    if not len(u) or u.min() < 1.0:
        return None
    return float(k * u.min())
