"""Fitting one time of day: samples from each photo, a coarse start, optimistix least squares.

Photos of one group share k, rho (and a sun correction when the sun is
fitted); each keeps its own lit levels (paper and ground) and a linear
brightness gradient (exposure, vignetting). Optional terms, the camera blur
and the penumbra profile, are chosen by BIC. Uncertainties come from the
Jacobian at the solution, scaled by the residual variance, or from a cluster-robust
sandwich over stretches of edge when that is larger, plus a calibrated systematic
term (``uncertainty``).
"""

from __future__ import annotations

import dataclasses
import time as _time
from typing import NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx
from jaxtyping import Array, Bool, Float, Int
from scipy.stats import median_abs_deviation

from softshadow import GroundGrid, Pose, SoftShadowModel, Sun
from softshadow.internal import bucket_size, concatenate_plans

from .model import (K_SCALE, FitConfig, FitParams, GroupArrays, Prediction, angular_pixel_gradient, predict,
                    raw_from_k, raw_from_rho, residuals, residuals_of)
from .options import FitOptions
from ..report.overlay import fitted_alpha_image
from ..samples.receiver_light import shadow_factor
from ..report.results import GroupResult, OverlayPlotData, ProfilePlotData
from .saved_programs import call_saved
from ..samples.ground import select_samples
from ..samples.photo_samples import NoShadowInView, PhotoSamples
from ..edges.cues import few_profiles_warning
from .uncertainty import cluster_covariance, combine_errors, edge_clusters, range_upper_bound, resolution_warning
from ..photos.views import PhotoView

__all__ = ["FitOptions", "fit_group", "Solution", "Trial", "KRho", "Identifiability", "sample_views",
           "initial_params", "plain_config", "start_grid", "plain_start", "choose_model", "covariance", "k_rho_with_errors",
           "penumbra_width_px", "SampleCounts", "sample_counts", "no_ramp_bound", "identifiability",
           "umbra_warning", "profile_plot_data"]

#: Levenberg-Marquardt tolerances (relative, absolute) on the parameters and on each residual
#: (residuals are relative to the lit level, whose noise is ~1e-2: 1e-4 is 1 % of it).
LM_RTOL, LM_ATOL = 1e-4, 1e-4
#: Singular values of J below this fraction of the largest count as zero (switched-off terms).
COV_RCOND = 1e-6
#: Not identifiable below this penumbra width (pixels) or above this relative error of k.
MIN_PENUMBRA_PX, MAX_K_REL_STDERR = 0.8, 0.5
#: Not identifiable when fewer samples than MIN_PENUMBRA_SAMPLES lie inside a fitted penumbra
#: (|u| < 1) narrower than NARROW_PENUMBRA_PX: its width, as wide as a camera's blur spot
#: (2 sqrt(1/12 + blur^2) = 1.6 px at 0.7 px of blur), and k then rest on a handful of pixels,
#: where a sharper shadow under the blur or JPEG fits as well (hard-cases preset, 320x240: the sun
#: at 5 deg read k 2.4x the truth from 16 samples of a 1.6 px penumbra, a shadow partly out of
#: frame 2.0x from 12; groups with penumbrae of 1.3-1.95 px that measured k had 185 or more,
#: and 26 samples of a 5.6 px penumbra measured k within 0.5 %: docs/uncertainty.md, "Counting
#: the samples").
MIN_PENUMBRA_SAMPLES, NARROW_PENUMBRA_PX = 40, 2.0
#: rho is not measured when fewer samples than this lie in the fitted umbra (alpha, blur included,
#: at least UMBRA_ALPHA): rho is the umbra's level, and without umbra pixels it comes from the
#: penumbra's model and trades off with k (a shadow a pixel or two wide, no umbra sample, read rho
#: 0.55 for 0.25; a long thin shadow at a low sun measured rho within 0.005 from 15).
MIN_UMBRA_SAMPLES, UMBRA_ALPHA = 5, 0.99


def _group_arrays(samples: list[PhotoSamples], views: list[PhotoView]) -> GroupArrays:
    """Stack the photos' samples into one padded set (one compiled solver for any group)."""
    counts = [len(s.observed) for s in samples]
    size = bucket_size(sum(counts), 1024)
    plan = concatenate_plans([s.plan for s in samples], counts, pad_to=size,
                             edge_pad_to=bucket_size(sum(int(s.plan.edges.outward_sign.shape[0])
                                                         for s in samples), 256))
    cat = lambda xs: np.concatenate(xs)
    pad = lambda x, fill=0.0: np.concatenate([x, np.full((size - len(x),) + x.shape[1:], fill, dtype=x.dtype)])
    scales = []
    for s in samples:
        lit = s.observed[np.asarray(s.plan.hard)[:len(s.observed)] < 0.5]
        scale = float(np.percentile(lit, 75)) if len(lit) else float(np.percentile(s.observed, 90))
        scales.append(max(scale, 1e-9))
    photo = cat([np.full(n, i, np.int32) for i, n in enumerate(counts)])
    return GroupArrays(
        ground=jnp.asarray(pad(cat([s.ground for s in samples]))),
        jac=jnp.asarray(pad(cat([s.jac for s in samples]))),
        observed=jnp.asarray(pad(cat([s.observed for s in samples]))),
        weight=jnp.asarray(pad(np.ones(sum(counts)))),
        photo=jnp.asarray(pad(photo, 0)),
        albedo_class=jnp.asarray(pad(cat([s.albedo_class.astype(np.int32) for s in samples]), 0)),
        uv_norm=jnp.asarray(pad(cat([s.uv_norm for s in samples]))), plan=plan,
        sun_azimuth_deg=jnp.asarray([float(v.sun_azimuth_deg) for v in views]),
        sun_elevation_deg=jnp.asarray([float(v.sun_elevation_deg) for v in views]),
        scale=jnp.asarray(scales), grad_t_pixel=jnp.zeros(size),
        sky_hidden=jnp.asarray(pad(cat([s.sky_hidden if s.sky_hidden is not None
                                        else np.zeros(len(s.observed)) for s in samples]))),
        sun_cos=jnp.asarray(pad(cat([s.sun_cos if s.sun_cos is not None
                                     else np.ones(len(s.observed)) for s in samples]), 1.0)))


def sample_views(model: SoftShadowModel, pose: Pose, views: list[PhotoView], options: FitOptions,
                 sky_model: SoftShadowModel | None = None) -> tuple[list[PhotoSamples], list[PhotoView], list[str]]:
    """Step 1: each photo's samples (``select_samples``; ``sky_model``: the mesh the hidden sky
    is cast from, default ``model``). Returns the samples, the views they come from, and a
    one-line warning for each photo with no shadow in view."""
    samples, used, warnings = [], [], []
    for i, view in enumerate(views):
        try:
            samples.append(select_samples(model, pose, view, options.range_k_max,
                                          max_samples=options.max_samples_per_photo, seed=options.seed + i,
                                          sky_occlusion=options.sky_occlusion, sky_model=sky_model))
            used.append(view)
        except NoShadowInView as exc:
            warnings.append(f"{view.name}: {exc}")
    return samples, used, warnings


def initial_params(samples: list[PhotoSamples]) -> tuple[FitParams, float]:
    """Step 2a: the start (k is set later from a grid, ``_prepare``): each photo's lit levels
    from the 75th percentile of its lit samples, rho from the median dark/lit ratio; also rho."""
    log_level = np.zeros((len(samples), 2))
    ratios = []
    for i, s in enumerate(samples):
        hard = np.asarray(s.plan.hard)[:len(s.observed)]
        for c in (0, 1):
            sel = s.albedo_class == c
            lit = s.observed[sel & (hard < 0.5)]
            dark = s.observed[sel & (hard > 0.5)]
            if len(lit) >= 5:
                log_level[i, c] = np.log(max(np.percentile(lit, 75), 1e-9))
                if len(dark) >= 5:
                    ratios.append(np.percentile(dark, 25) / max(np.percentile(lit, 75), 1e-9))
            else:
                other = s.observed[hard < 0.5]
                log_level[i, c] = np.log(max(np.percentile(other, 75) if len(other) else 1.0, 1e-9))
    rho0 = float(np.clip(np.median(ratios) if ratios else 0.3, 0.02, 0.98))
    f64 = lambda x: jnp.asarray(x, dtype=jnp.float64)  # not weakly typed: one compiled solver
    params = FitParams(raw_k=f64(0.0), raw_rho=f64(raw_from_rho(rho0)), raw_blur=f64(np.zeros(len(samples))),
                       sun_delta_deg=f64(np.zeros(2)), log_level=f64(log_level),
                       gradient=f64(np.zeros((len(samples), 2))))
    return params, rho0


class Solution(eqx.Module):
    """One Levenberg-Marquardt solve, everything at its solution.

    params: the solution; converged, steps: the solver's outcome; residuals (n,); jacobian
    (n, p): d residuals / d ``params.vector()``, columns in ``FitParams.layout`` order;
    prediction: ``predict`` there; grad_t_pixel (n,): the samples' |dT/dpixel| used.
    """

    params: FitParams
    converged: Bool[Array, ""]
    steps: Int[Array, ""]
    residuals: Float[Array, " n"]
    jacobian: Float[Array, "n p"]
    prediction: Prediction
    grad_t_pixel: Float[Array, " n"]


class Trial(NamedTuple):
    """One solve of one configuration: its BIC and residual sum of squares, and the solution
    with NumPy residuals, Jacobian and prediction (``params`` stay JAX: they start the next solve)."""

    bic: float
    rss: float
    config: FitConfig
    solution: Solution


def _bic(rss: float, n: int, n_free: int) -> float:
    return n * np.log(max(rss, 1e-300) / n) + n_free * np.log(n)


def _n_free(config: FitConfig, n_photos: int) -> int:
    """Parameters a configuration really fits (switched-off terms do not count)."""
    return 2 + 4 * n_photos + n_photos * int(float(config.fit_blur)) + 2 * int(float(config.fit_sun))


def _k_np(raw) -> float:
    """k from raw_k in NumPy (post-processing stays out of JAX's eager dispatch)."""
    return float(K_SCALE * np.logaddexp(0.0, float(raw)))


def _rho_np(raw) -> float:
    return float(1.0 / (1.0 + np.exp(-float(raw))))


def _prepare(params: FitParams, raw_ks, group: GroupArrays, pose: Pose, config: FitConfig):
    """The samples' |dT/dpixel| (n,) and the raw_k (of the grid raw_ks) with the least plain
    sum of squares, blur and sun switched off and the other parameters fixed: the start."""
    grad_t_pixel = angular_pixel_gradient(group, pose, 0.01, config.rule)
    zero = jnp.zeros_like(config.fit_blur)
    coarse = (dataclasses.replace(group, grad_t_pixel=grad_t_pixel), pose,
              dataclasses.replace(config, fit_blur=zero, fit_sun=zero, huber_delta=zero))
    losses = jax.vmap(lambda rk: jnp.sum(residuals(dataclasses.replace(params, raw_k=rk), coarse) ** 2))(raw_ks)
    return grad_t_pixel, raw_ks[jnp.argmin(losses)]


def _solve(params: FitParams, args, max_steps: int, start_raw_ks, prepare) -> Solution:
    """Levenberg-Marquardt from ``params``; the ``Solution`` with the residuals' Jacobian
    computed at the solution (forward mode: n rows, few columns).

    With ``prepare`` true (a traced switch, so one compiled program serves every call), the
    group's first solve: |dT/dpixel| is computed and raw_k starts at the best value of the
    grid ``start_raw_ks`` (m,) (``_prepare``). The program is saved between processes when
    the command line asks for it (``fitting.solve.saved_programs``)."""
    vector, converged, steps, r, jac, *rest = call_saved(
        "fitting.solve.group", _solve_arrays, params, args, max_steps, start_raw_ks, prepare)
    pred, grad_t_pixel = Prediction(*rest[:-1]), rest[-1]
    return Solution(FitParams.from_vector(np.asarray(vector), params.n_photos), converged, steps, r, jac, pred, grad_t_pixel)


def _solve_arrays(params: FitParams, args, max_steps: int, start_raw_ks, prepare) -> tuple:
    """``_solve``'s program: the solution as a tuple of arrays (parameter vector, converged,
    steps, residuals, Jacobian, the prediction's fields, |dT/dpixel|)."""
    group, pose, config = args
    grad_t_pixel, raw_k = jax.lax.cond(
        prepare, lambda: _prepare(params, start_raw_ks, group, pose, config),
        lambda: (group.grad_t_pixel, params.raw_k))
    group = dataclasses.replace(group, grad_t_pixel=grad_t_pixel)
    params = dataclasses.replace(params, raw_k=raw_k)
    args = (group, pose, config)
    solver = optx.LevenbergMarquardt(rtol=LM_RTOL, atol=LM_ATOL)
    sol = optx.least_squares(residuals, solver, params, args=args, max_steps=max_steps, throw=False)
    n_photos = params.n_photos

    def at(x):  # residuals, with the prediction they come from (one trace of the edge geometry)
        p = FitParams.from_vector(x, n_photos)
        pred = predict(p, group, pose, config)
        r = residuals_of(pred, group, config)
        return r, (r, pred)

    jac, (r, pred) = jax.jacfwd(at, has_aux=True)(sol.value.vector())
    return (sol.value.vector(), sol.result == optx.RESULTS.successful, sol.stats["num_steps"], r, jac, *pred,
            group.grad_t_pixel)


def _to_numpy(sol: Solution) -> Solution:
    """The solution's arrays as NumPy (post-processing runs no eager JAX), params kept as they are."""
    as_np = lambda x: np.asarray(x)
    return dataclasses.replace(sol, converged=bool(sol.converged), steps=int(sol.steps),
                               residuals=as_np(sol.residuals), jacobian=as_np(sol.jacobian),
                               prediction=Prediction(*map(as_np, sol.prediction)),
                               grad_t_pixel=as_np(sol.grad_t_pixel))


def robust_delta(r: np.ndarray, robust: bool) -> float:
    """The pseudo-Huber scale: 3 sigma of the plain fit's residuals (r (n,), padding rows
    exactly 0 are left out), sigma from their median absolute deviation; 0 when not robust."""
    r = np.asarray(r)
    r = r[r != 0]
    sigma = float(median_abs_deviation(r, scale="normal")) if len(r) else 1e-3
    return float(max(3.0 * sigma, 1e-6)) if robust else 0.0


def plain_config(options: FitOptions, fit_sun: bool) -> FitConfig:
    """The first solve's configuration: the first candidate profile, blur free when allowed,
    plain least squares (no robust loss)."""
    return FitConfig.make(options.profiles[0], True in options.blur, fit_sun, 0.0, options.rule)


def start_grid(options: FitOptions):
    """The coarse log grid of raw_k (9,) the first solve starts from (its best point)."""
    return jnp.asarray(raw_from_k(np.geomspace(5e-4, options.range_k_max, 9)))


def plain_start(arrays: GroupArrays, pose: Pose, base: FitParams, options: FitOptions, fit_sun: bool
                ) -> tuple[Solution, GroupArrays, float]:
    """Step 2b: a plain least-squares pass (blur free) from the best k of a coarse log grid
    (the loss is flat where the band misses the penumbra). Returns its solution, the arrays
    with their |dT/dpixel|, and the robust loss's scale it sets (``robust_delta``)."""
    sol = _to_numpy(_solve(base, (arrays, pose, plain_config(options, fit_sun)), options.max_steps,
                           start_grid(options), jnp.asarray(True)))
    arrays = dataclasses.replace(arrays, grad_t_pixel=jnp.asarray(sol.grad_t_pixel))
    return sol, arrays, robust_delta(sol.residuals, options.robust)


def covariance(r: np.ndarray, jac: np.ndarray, n_eff: int) -> tuple[np.ndarray, float]:
    """Parameter covariance (p, p) from the SVD of J (n, p): V S^-2 V^T times the residual
    variance s2 (singular values below COV_RCOND of the largest, such as switched-off
    terms' zero columns, count as zero); also s2. Unlike pinv(J^T J), this does not square
    J's condition number."""
    dof = max(n_eff - jac.shape[1], 1)
    s2 = float(r @ r) / dof
    _, sv, vt = np.linalg.svd(jac, full_matrices=False)
    keep = sv > COV_RCOND * (sv[0] if len(sv) else 0.0)
    inv_sq = np.where(keep, 1.0 / np.where(keep, sv, 1.0) ** 2, 0.0)
    return (vt.T * inv_sq) @ vt * s2, s2


def choose_model(arrays: GroupArrays, pose: Pose, start: FitParams, options: FitOptions, fit_sun: bool,
                 delta: float, n_eff: int, log=None) -> tuple[Trial, np.ndarray, float]:
    """Step 3: the robust fit of each candidate profile (blur free), the lowest BIC kept;
    then blur kept or dropped by BIC. Returns the best trial, its covariance and s2.

    log: called with a line per solve when given."""
    n_photos = start.n_photos
    grid = jnp.zeros(9)  # not used after the first solve (``prepare`` off)

    def run(profile, blur, init):
        cfg = FitConfig.make(profile, blur, fit_sun, delta, options.rule)
        sol = _to_numpy(_solve(init, (arrays, pose, cfg), options.max_steps, grid, jnp.asarray(False)))
        rss = float(sol.residuals @ sol.residuals)
        bic = _bic(rss, n_eff, _n_free(cfg, n_photos))
        if log:
            log(f"profile {profile} blur {blur}: {sol.steps} steps, ok {sol.converged}, BIC {bic:.1f}")
        return Trial(bic, rss, cfg, sol)

    blur_first = True in options.blur
    # Profiles are compared with blur free, each solve starting from the previous solution.
    best = None
    for profile in options.profiles:
        trial = run(profile, blur_first, start if best is None else best.solution.params)
        if best is None or trial.bic < best.bic:
            best = trial
    cov, s2 = covariance(best.solution.residuals, best.solution.jacobian, n_eff)
    if blur_first and False in options.blur:
        # BIC without blur, from the fit with it: the nested model's residual sum of squares is
        # RSS + b^T ([(J^T J)^-1]_bb)^-1 b to second order (b: the photos' blurs; exact for a
        # linear model), so a solve without blur is needed only when BIC prefers it.
        i_blur = FitParams.layout(n_photos)["raw_blur"]
        inv_jtj = cov[i_blur, i_blur] / max(s2, 1e-300)
        raw_blur = np.asarray(best.solution.params.raw_blur, dtype=np.float64).reshape(-1)
        rss_no_blur = best.rss + float(raw_blur @ np.linalg.pinv(inv_jtj, rcond=COV_RCOND) @ raw_blur)
        no_blur_cfg = FitConfig.make(best.config.profile, False, fit_sun, delta, options.rule)
        bic_no_blur = _bic(rss_no_blur, n_eff, _n_free(no_blur_cfg, n_photos))
        if log:
            log(f"BIC without blur, to second order: {bic_no_blur:.1f}")
        # Worth a solve only when the estimate wins by more than 2 (a BIC difference under 2
        # is not evidence either way; the blur fit contains no blur as blur ~ 0); the solve is
        # kept only if its real BIC is lower too.
        if bic_no_blur < best.bic - 2.0:
            params = best.solution.params
            trial = run(best.config.profile, False,
                        dataclasses.replace(params, raw_blur=jnp.zeros_like(params.raw_blur)))
            if trial.bic < best.bic:
                best = trial
                cov, s2 = covariance(best.solution.residuals, best.solution.jacobian, n_eff)
    return best, cov, s2


class KRho(NamedTuple):
    """k and rho with their one-sigma errors (physical units)."""

    range_k: float
    rho: float
    range_stderr: float
    rho_stderr: float


def k_rho_with_errors(params: FitParams, cov: np.ndarray) -> KRho:
    """Step 4: k, rho and their standard errors through the reparameterisation (first order:
    dk/draw_k = K_SCALE sigmoid(raw_k), drho/draw_rho = rho (1 - rho)); cov (p, p) in
    ``FitParams.layout`` order."""
    lay = FitParams.layout(params.n_photos)
    ik, ir = lay["raw_k"].start, lay["raw_rho"].start
    k, rho = _k_np(params.raw_k), _rho_np(params.raw_rho)
    dk = K_SCALE * _rho_np(params.raw_k)  # d softplus = sigmoid
    drho = rho * (1 - rho)
    var_k, var_rho = cov[ik, ik] * dk ** 2, cov[ir, ir] * drho ** 2
    return KRho(k, rho, float(np.sqrt(max(var_k, 0.0))), float(np.sqrt(max(var_rho, 0.0))))


def _photo_slices(samples: list[PhotoSamples]) -> list[slice]:
    ends = np.cumsum([0] + [len(s.observed) for s in samples])
    return [slice(int(a), int(b)) for a, b in zip(ends[:-1], ends[1:])]


def penumbra_width_px(samples: list[PhotoSamples], prediction: Prediction) -> tuple[float | None, float | None]:
    """Step 5a: median and interquartile range of the penumbra's width in image pixels
    (2 / |du/dpixel|) over the samples inside it (|u| < 1); (None, None) when none is."""
    widths = []
    for sl in _photo_slices(samples):
        inside = np.abs(prediction.u[sl]) < 1
        if inside.any():
            widths.append(2.0 / np.maximum(prediction.slope[sl][inside], 1e-12))
    if not widths:
        return None, None
    w = np.concatenate(widths)
    q75, q25 = np.percentile(w, [75, 25])
    return float(np.median(w)), float(q75 - q25)


def no_ramp_bound(samples: list[PhotoSamples], prediction: Prediction, k: float) -> float | None:
    """Step 5a': when no sample lies inside the fitted penumbra (|u| >= 1 everywhere), the largest k
    the samples allow: the penumbra's half-width grows in proportion to k, so the penumbra of
    k * min |u| would just reach the nearest sample, which shows no ramp. None when every sample
    lies beyond the planned bands (u = +-1e6: no bound from them)."""
    n = sum(len(s.observed) for s in samples)
    u = np.abs(np.asarray(prediction.u, dtype=np.float64)[:n])
    u = u[u < 1e5]
    return float(k * u.min()) if len(u) else None


class SampleCounts(NamedTuple):
    """How many of the fit's samples (padding left out) the fitted shadow puts inside the
    penumbra (|u| < 1) and in the umbra (alpha >= UMBRA_ALPHA, the pixel's blur included)."""

    penumbra: int
    umbra: int


def sample_counts(samples: list[PhotoSamples], prediction: Prediction) -> SampleCounts:
    """Step 5a: ``SampleCounts`` of the photos' samples under ``prediction``."""
    n = sum(len(s.observed) for s in samples)
    u, alpha = np.asarray(prediction.u)[:n], np.asarray(prediction.alpha)[:n]
    return SampleCounts(int(np.count_nonzero(np.abs(u) < 1)), int(np.count_nonzero(alpha >= UMBRA_ALPHA)))


def umbra_warning(n_umbra: int) -> str | None:
    """The warning (the group is then not reliable) for a fit with fewer than MIN_UMBRA_SAMPLES
    samples in the fitted umbra, or None."""
    if n_umbra >= MIN_UMBRA_SAMPLES:
        return None
    return (f"rho not measured: only {n_umbra} samples lie in the fitted umbra (fewer than "
            f"{MIN_UMBRA_SAMPLES}), so rho rests on the penumbra's model")


class Identifiability(NamedTuple):
    """Whether k was measured; when not, range_k is an upper bound and ``warning`` says so."""

    identifiable: bool
    range_k: float
    warning: str | None


def identifiability(k: float, k_stderr: float, penumbra_px: float | None,
                    bound_stderr: float | None = None, n_penumbra: int | None = None) -> Identifiability:
    """Step 5b: k is not identifiable when the penumbra is narrower than MIN_PENUMBRA_PX
    (or not seen), when it is narrower than NARROW_PENUMBRA_PX and fewer than
    MIN_PENUMBRA_SAMPLES samples lie inside it (``n_penumbra``; None: not checked), or when
    k is lost in its own noise (statistical error ``k_stderr``
    above MAX_K_REL_STDERR of k). Then the reported range_k is an upper bound: k + 2 sigma
    (sigma = ``bound_stderr``, the stated error with its systematic part, when given; else
    ``k_stderr``), and at least the k whose penumbra would be one pixel wide
    (k / penumbra_px, the width scaling with k)."""
    resolved = penumbra_px is not None and penumbra_px >= MIN_PENUMBRA_PX
    seen = n_penumbra is None or n_penumbra >= MIN_PENUMBRA_SAMPLES or (resolved and penumbra_px >= NARROW_PENUMBRA_PX)
    if resolved and seen and k_stderr <= MAX_K_REL_STDERR * max(k, 1e-12):
        return Identifiability(True, float(k), None)
    upper = range_upper_bound(k, k_stderr, penumbra_px, bound_stderr)
    if resolved and not seen:
        # Blur and JPEG widen a penumbra that few pixels sample: k reads high, so it bounds k.
        return Identifiability(False, float(upper), f"range not identifiable: only {n_penumbra} samples lie "
                               f"inside the fitted penumbra (fewer than {MIN_PENUMBRA_SAMPLES}); range_k is "
                               "an upper bound")
    return Identifiability(False, float(upper), "range not identifiable: the penumbra is narrower than "
                           "the resolution; range_k is an upper bound")


def profile_plot_data(samples: list[PhotoSamples], prediction: Prediction, rho: float,
                      sky_hidden: np.ndarray, sun_cos: np.ndarray) -> list[ProfilePlotData]:
    """Step 6a: observed and fitted values across the edge for each photo, normalised by the
    fitted lit level, against the signed distance (pixels) from the hard-shadow boundary."""
    out = []
    pred, alpha, u, slope = prediction.values, prediction.alpha, prediction.u, prediction.slope
    for s, sl in zip(samples, _photo_slices(samples)):
        lvl = pred[sl] / np.maximum(shadow_factor(alpha[sl], rho, sun_cos[sl], 1 - sky_hidden[sl]), 1e-9)
        dist = np.where(slope[sl] > 0, u[sl] / np.maximum(slope[sl], 1e-12), np.nan)
        out.append(ProfilePlotData(s.name, dist, s.observed / lvl, pred[sl] / lvl, s.profile_id))
    return out


def _overlay(model: SoftShadowModel, pose: Pose, view: PhotoView, params: FitParams, cfg: FitConfig,
             s: PhotoSamples, max_side: int = 480) -> OverlayPlotData:
    """Step 6b: the fitted alpha over a downsampled copy of the photo, for the overlay plot."""
    import cv2
    h, w = view.shape
    f = min(1.0, max_side / max(h, w))
    sw, sh = max(int(round(w * f)), 1), max(int(round(h * f)), 1)
    small = cv2.resize(view.gray.astype(np.float32), (sw, sh), interpolation=cv2.INTER_AREA)
    d = np.asarray(params.sun_delta_deg) * float(cfg.fit_sun)
    sun = Sun(view.sun_azimuth_deg + d[0], view.sun_elevation_deg + d[1])
    if view.grid is not None:
        g = view.grid
        p = g.pixel_m * w / sw
        small_view = GroundGrid(p, (g.origin_m[0] + (p - g.pixel_m) / 2,
                                    g.origin_m[1] - (p - g.pixel_m) / 2), sw, sh)
    else:
        small_view = view.camera.with_size(sw, sh)
    alpha = fitted_alpha_image(model.with_options(profile=cfg.profile), pose, sun,
                               _k_np(params.raw_k), small_view)
    return OverlayPlotData(view.name, small, alpha, s.uv, photo_shape=(h, w))


def fit_group(model: SoftShadowModel, pose: Pose, views: list[PhotoView], label: str,
              time_label: str | None, options: FitOptions | None = None,
              sky_model: SoftShadowModel | None = None, samples: tuple | None = None) -> GroupResult:
    """Fit k and rho shared by ``views`` (one time of day). Never raises for bad data:
    failures come back as a GroupResult with ``error`` set. sky_model: the mesh the hidden sky
    is cast from (a coarse level of detail, ``fitting.solve.lod``; default ``model``); samples:
    (view names, then ``sample_views``' samples, views and warnings) drawn already with this
    model, options and sky model (the level-of-detail choice draws them); used when the names
    are those of ``views``, else the samples are drawn here."""
    options = options or FitOptions()
    start = _time.perf_counter()
    result = GroupResult(label=label, time=time_label, photos=[v.name for v in views])
    if samples is not None and tuple(samples[0]) == tuple(v.name for v in views):
        samples, used, result.warnings = samples[1], samples[2], list(samples[3])
    else:
        samples, used, result.warnings = sample_views(model, pose, views, options, sky_model)
    if not samples:
        result.error = "no shadow in view: " + "; ".join(result.warnings)
        result.seconds = _time.perf_counter() - start
        return result
    fit_sun = any(v.sun_source == "fitted" for v in used)
    solve_start = _time.perf_counter()
    arrays = _group_arrays(samples, used)
    n_eff = sum(len(s.observed) for s in samples)
    base, _ = initial_params(samples)
    plain, arrays, delta = plain_start(arrays, pose, base, options, fit_sun)
    log = (lambda line: print(f"  {label}: {line}")) if options.verbose else None
    best, cov, _ = choose_model(arrays, pose, plain.params, options, fit_sun, delta, n_eff, log)
    sol, cfg = best.solution, best.config
    result.solve_seconds = _time.perf_counter() - solve_start
    est = k_rho_with_errors(sol.params, cov)
    clusters = edge_clusters([s.profile_id for s in samples], len(sol.residuals))
    robust = k_rho_with_errors(sol.params, cluster_covariance(sol.residuals, sol.jacobian, clusters))
    result.rho = est.rho
    result.profile = cfg.profile
    # One number for the group: the root mean square of the photos' blurs (px).
    raw_blur = np.asarray(sol.params.raw_blur, dtype=np.float64)
    result.blur_px = float(np.sqrt(np.mean(np.maximum(raw_blur, 0.0)))) if float(cfg.fit_blur) else None
    result.rmse = float(np.sqrt(best.rss / n_eff))
    result.converged = sol.converged
    result.n_samples = n_eff
    result.n_profiles = int(sum(s.n_profiles for s in samples))
    errors = [v.reprojection_error_px for v in used if v.reprojection_error_px is not None]
    result.reprojection_error_px = max(errors) if errors else None
    d = np.asarray(sol.params.sun_delta_deg) * float(cfg.fit_sun)
    result.sun_azimuth_deg = float(used[0].sun_azimuth_deg) + float(d[0])
    result.sun_elevation_deg = float(used[0].sun_elevation_deg) + float(d[1])
    result.sun_source = used[0].sun_source
    result.penumbra_px, result.penumbra_px_iqr = penumbra_width_px(samples, sol.prediction)
    errors = combine_errors(est.range_k, est.rho, (est.range_stderr, est.rho_stderr),
                            (robust.range_stderr, robust.rho_stderr), result.penumbra_px)
    result.range_stderr, result.rho_stderr = errors.range_stderr, errors.rho_stderr
    result.range_stderr_stat, result.rho_stderr_stat = errors.range_stderr_stat, errors.rho_stderr_stat
    result.range_stderr_sys, result.rho_stderr_sys = errors.range_stderr_sys, errors.rho_stderr_sys
    counts = sample_counts(samples, sol.prediction)
    ident = identifiability(est.range_k, errors.range_stderr_stat, result.penumbra_px, errors.range_stderr,
                            counts.penumbra)
    result.identifiable, result.range_k = ident.identifiable, ident.range_k
    if not ident.identifiable and result.penumbra_px is None:
        # No sample inside the penumbra (the object hides it from the camera, or it is far below a
        # pixel): k + 2 sigma bounds nothing there, since k did not move from its start.
        bound = no_ramp_bound(samples, sol.prediction, est.range_k)
        result.range_k = max(result.range_k, bound) if bound is not None else result.range_k
    if ident.warning:
        result.warnings.append(ident.warning)
    elif resolution_warning(result.penumbra_px, result.blur_px):
        result.warnings.append(resolution_warning(result.penumbra_px, result.blur_px))
    if umbra_warning(counts.umbra):
        result.warnings.append(umbra_warning(counts.umbra))
        result.reliable = False
    if options.plots:
        result.plot_profiles = profile_plot_data(samples, sol.prediction, est.rho, np.asarray(arrays.sky_hidden),
                                                  np.asarray(arrays.sun_cos))
        result.plot_overlays = [_overlay(model, pose, used[i], sol.params, cfg, samples[i])
                                for i in range(len(samples))
                                if options.overlays == "all" or (options.overlays == "first" and i == 0)]
    if not sol.converged:
        result.warnings.append("the solver stopped before converging")
    if few_profiles_warning(result.n_profiles):
        # Too little of the outline in view: one stretch of edge decides k and rho.
        result.warnings.append(few_profiles_warning(result.n_profiles))
        result.reliable = False
    result.seconds = _time.perf_counter() - start
    return result
