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
from jaxtyping import ArrayLike, Bool, Float, Int
from scipy.stats import median_abs_deviation

from softshadow import GroundGrid, Pose, SoftShadowModel, Sun
from softshadow.internal import bucket_size, concatenate_plans

from .model import (K_SCALE, FitConfig, FitParams, GroupArrays, Prediction, angular_pixel_gradient, k_rho_slopes,
                    predict,
                    raw_from_k, raw_from_rho, residuals, residuals_of)
from .options import FitOptions
from .rule_choice import RuleChoice, choose_rule, sampling_rule, wedge_footprints, wedge_plan, wedge_unavailable
from ..report.overlay import fitted_alpha_image
from ..samples.receiver_light import shadow_factor
from ..report.results import FitDiagnostics, GroupResult, OverlayPlotData, PlotData, ProfilePlotData, SunUsed
from .saved_programs import call_saved
from ..samples.ground import select_samples
from ..samples.photo_samples import NoShadowInView, PhotoSamples
from .evidence import no_ramp_k, penumbra_px_per_k, photos_evidence, remaining_step_se
from .uncertainty import cluster_covariance, combine_errors, edge_clusters
from ..verdict.evidence import FitEvidence, GroupContext, SunFree
from ..verdict.rules import judge_fit
from ..photos.views import PhotoView

__all__ = ["FitOptions", "fit_group", "Solution", "Trial", "KRho", "sample_views", "UMBRA_ALPHA",
           "initial_params", "plain_config", "start_grid", "plain_start", "choose_model", "covariance", "k_rho_with_errors",
           "penumbra_width_px", "SampleCounts", "sample_counts", "profile_plot_data"]

#: Levenberg-Marquardt tolerances (relative, absolute) on the parameters and on each residual
#: (residuals are relative to the lit level, whose noise is ~1e-2: 1e-4 is 1 % of it).
LM_RTOL, LM_ATOL = 1e-4, 1e-4
#: Singular values of J below this fraction of the largest count as zero (switched-off terms).
COV_RCOND = 1e-6
#: A sample is in the fitted umbra when its alpha (blur included) is at least this.
UMBRA_ALPHA = 0.99


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


def _with_wedge(arrays: GroupArrays, model: SoftShadowModel, pose: Pose, samples: list[PhotoSamples],
                views: list[PhotoView], options: FitOptions, params: FitParams, config: FitConfig) -> GroupArrays:
    """The arrays with the ``wedge`` rule's plan at the samples, over each pixel widened by its
    photo's camera blur in the fit (params, config) it follows (``rule_choice.wedge_footprints``)."""
    blur = np.asarray(params.raw_blur, np.float64).reshape(-1) * float(config.fit_blur)
    axes = wedge_footprints(samples, blur, int(arrays.observed.shape[0]))
    return dataclasses.replace(arrays, wedge_plan=wedge_plan(model, pose, samples, views, options.range_k_max, axes),
                               wedge_axes=jnp.asarray(axes))


def _wedge_fit(arrays: GroupArrays, model: SoftShadowModel, pose: Pose, samples: list[PhotoSamples],
               views: list[PhotoView], options: FitOptions, plain: Solution, fit_sun: bool, delta: float,
               n_eff: int, log=None) -> tuple[Trial, np.ndarray, GroupArrays]:
    """The ``wedge`` rule's fit (asked for, or taken by ``auto``: one path, so both read the same):
    its plan over the footprints of the plain ``edge`` solve's camera blur, ``choose_model`` from
    that solve's solution; then planned again over the footprints of that fit's own blur and
    solved again from it. The edge rule reads the blur low where edges crowd (the real dragon:
    0.44-0.68 px for 0.57-0.76), which left the wedge rule's excess too sharp and k about 1 % high.
    Returns the best trial, its covariance and the arrays with the plan."""
    arrays = _with_wedge(arrays, model, pose, samples, views, options, plain.params, plain_config(options, fit_sun))
    first, _, _ = choose_model(arrays, pose, plain.params, options, fit_sun, delta, n_eff, log, "wedge")
    arrays = _with_wedge(arrays, model, pose, samples, views, options, first.solution.params, first.config)
    best, cov, _ = choose_model(arrays, pose, first.solution.params, options, fit_sun, delta, n_eff, log, "wedge")
    return best, cov, arrays


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
    converged: Bool[ArrayLike, ""]
    steps: Int[ArrayLike, ""]
    residuals: Float[ArrayLike, " n"]
    jacobian: Float[ArrayLike, "n p"]
    prediction: Prediction
    grad_t_pixel: Float[ArrayLike, " n"]


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
    grid ``start_raw_ks`` (m,) (``_prepare``; not under the ``wedge`` rule, whose solves start from
    a prepared edge solve: there ``prepare`` is ignored). The program is saved between processes when
    the command line asks for it (``fitting.solve.saved_programs``)."""
    vector, converged, steps, r, jac, *rest = call_saved(
        "fitting.solve.group", _solve_arrays, params, args, max_steps, start_raw_ks, prepare)
    pred, grad_t_pixel = Prediction(*rest[:-1]), rest[-1]
    return Solution(FitParams.from_vector(np.asarray(vector), params.n_photos), converged, steps, r, jac, pred, grad_t_pixel)


def _solve_arrays(params: FitParams, args, max_steps: int, start_raw_ks, prepare) -> tuple:
    """``_solve``'s program: the solution as a tuple of arrays (parameter vector, converged,
    steps, residuals, Jacobian, the prediction's fields, |dT/dpixel|)."""
    group, pose, config = args
    if config.rule == "wedge":
        # The wedge rule's solves always start from the plain edge solve (``fit_group``), which
        # prepared the start; a grid of losses here would compile the wedge rule's forward once more.
        grad_t_pixel, raw_k = group.grad_t_pixel, params.raw_k
    else:
        grad_t_pixel, raw_k = jax.lax.cond(
            prepare, lambda: _prepare(params, start_raw_ks, group, pose, config),
            lambda: (group.grad_t_pixel, params.raw_k))
    group = dataclasses.replace(group, grad_t_pixel=grad_t_pixel)
    params = dataclasses.replace(params, raw_k=raw_k)
    args = (group, pose, config)
    solver: optx.LevenbergMarquardt = optx.LevenbergMarquardt(rtol=LM_RTOL, atol=LM_ATOL)
    sol: optx.Solution = optx.least_squares(residuals, solver, params, args=args, max_steps=max_steps, throw=False)
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


def plain_config(options: FitOptions, fit_sun: bool, rule: str | None = None) -> FitConfig:
    """The first solve's configuration: the first candidate profile, blur free when allowed,
    plain least squares (no robust loss); rule: default the options' sampling rule (``edge`` for
    the ``wedge`` and ``auto`` rules, whose plan follows this solve: ``fit_group``)."""
    return FitConfig.make(options.profiles[0], True in options.blur, fit_sun, 0.0, rule or sampling_rule(options.rule))


def start_grid(options: FitOptions):
    """The coarse log grid of raw_k (9,) the first solve starts from (its best point)."""
    return jnp.asarray(raw_from_k(np.geomspace(5e-4, options.range_k_max, 9)))


def plain_start(arrays: GroupArrays, pose: Pose, base: FitParams, options: FitOptions, fit_sun: bool,
                rule: str | None = None) -> tuple[Solution, GroupArrays, float]:
    """Step 2b: a plain least-squares pass (blur free) from the best k of a coarse log grid
    (the loss is flat where the band misses the penumbra). Returns its solution, the arrays
    with their |dT/dpixel|, and the robust loss's scale it sets (``robust_delta``). rule: as
    ``plain_config``."""
    sol = _to_numpy(_solve(base, (arrays, pose, plain_config(options, fit_sun, rule)), options.max_steps,
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
                 delta: float, n_eff: int, log=None, rule: str | None = None) -> tuple[Trial, np.ndarray, float]:
    """Step 3: the robust fit of each candidate profile (blur free), the lowest BIC kept;
    then blur kept or dropped by BIC. Returns the best trial, its covariance and s2.

    log: called with a line per solve when given; rule: the penumbra's rule (default the
    options' sampling rule, ``sampling_rule``)."""
    n_photos = start.n_photos
    rule = rule or sampling_rule(options.rule)
    grid = jnp.zeros(9)  # not used after the first solve (``prepare`` off)

    def run(profile, blur, init):
        cfg = FitConfig.make(profile, blur, fit_sun, delta, rule)
        sol = _to_numpy(_solve(init, (arrays, pose, cfg), options.max_steps, grid, jnp.asarray(False)))
        rss = float(sol.residuals @ sol.residuals)
        bic = _bic(rss, n_eff, _n_free(cfg, n_photos))
        if log:
            log(f"rule {rule} profile {profile} blur {blur}: {sol.steps} steps, ok {sol.converged}, BIC {bic:.1f}")
        return Trial(bic, rss, cfg, sol)

    blur_first = True in options.blur
    # Profiles are compared with blur free, each solve starting from the previous solution.
    best = None
    for profile in options.profiles:
        trial = run(profile, blur_first, start if best is None else best.solution.params)
        if best is None or trial.bic < best.bic:
            best = trial
    assert best is not None  # FitOptions.profiles is never empty
    cov, s2 = covariance(best.solution.residuals, best.solution.jacobian, n_eff)
    if blur_first and False in options.blur:
        # BIC without blur, from the fit with it: the nested model's residual sum of squares is
        # RSS + b^T ([(J^T J)^-1]_bb)^-1 b to second order (b: the photos' blurs; exact for a
        # linear model), so a solve without blur is needed only when BIC prefers it.
        i_blur = FitParams.layout(n_photos)["raw_blur"]
        inv_jtj = cov[i_blur, i_blur] / max(s2, 1e-300)
        raw_blur = np.asarray(best.solution.params.raw_blur, dtype=np.float64).reshape(-1)
        rss_no_blur = best.rss + float(raw_blur @ np.linalg.pinv(inv_jtj, rcond=COV_RCOND) @ raw_blur)
        no_blur_cfg = FitConfig.make(best.config.profile, False, fit_sun, delta, rule)
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
    dk, drho = k_rho_slopes(params.raw_k, params.raw_rho)
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
              sky_model: SoftShadowModel | None = None, *, fit_sun: bool | None = None,
              samples: tuple | None = None) -> GroupResult:
    """Fit k and rho shared by ``views`` (one time of day), judged by the rule book
    (``fitting.verdict.rules``) on this fit alone. Never raises for bad data: failures come back as
    a GroupResult with ``error`` set. sky_model: the mesh the hidden sky is cast from (a coarse
    level of detail, ``fitting.solve.lod``; default ``model``). fit_sun: fit the sun's azimuth and
    elevation with k and rho (default: when a view's sun is "fitted"). samples: (view names, then
    ``sample_views``' samples, views and warnings) drawn already with this model, options and sky
    model (the level-of-detail choice draws them); used when the names are those of ``views``,
    else the samples are drawn here."""
    options = options or FitOptions()
    start = _time.perf_counter()
    if model.rule == "wedge":  # samples and the nearest edges come from the edge rule's plan
        model = model.with_options(rule=sampling_rule(options.rule))
    names = [v.name for v in views]
    if samples is not None and tuple(samples[0]) == tuple(names):
        samples, used, no_shadow = samples[1], samples[2], list(samples[3])
    else:
        samples, used, no_shadow = sample_views(model, pose, views, options, sky_model)
    if not samples:
        return GroupResult.failed(label, time_label, names, "no shadow in view: " + "; ".join(no_shadow),
                                  warnings=no_shadow,
                                  diagnostics=FitDiagnostics(seconds=_time.perf_counter() - start))
    if fit_sun is None:
        fit_sun = any(v.sun_source == "fitted" for v in used)
    solve_start = _time.perf_counter()
    arrays = _group_arrays(samples, used)
    n_eff = sum(len(s.observed) for s in samples)
    base, _ = initial_params(samples)
    # The wedge and auto rules start as the edge rule does: its solve sets the camera blur the
    # wedge rule's plan is made for (``_with_wedge``).
    rule = sampling_rule(options.rule)
    plain, arrays, delta = plain_start(arrays, pose, base, options, fit_sun, rule)
    log = (lambda line: print(f"  {label}: {line}")) if options.verbose else None
    # A rule asked for that cannot be planned is said in a warning, not dropped silently.
    unplanned = wedge_unavailable(samples, used) if options.rule in ("wedge", "auto") else None
    wedge = options.rule in ("wedge", "auto") and unplanned is None
    fit_wedge = lambda: _wedge_fit(arrays, model, pose, samples, used, options, plain, fit_sun, delta, n_eff, log)
    if options.rule == "wedge" and wedge:
        best, cov, arrays = fit_wedge()
        choice = RuleChoice("wedge", reason="asked for")
    else:
        best, cov, _ = choose_model(arrays, pose, plain.params, options, fit_sun, delta, n_eff, log, rule)
        if options.rule == "auto" and wedge:
            at_edge = _with_wedge(arrays, model, pose, samples, used, options, best.solution.params, best.config)
            choice = choose_rule(best.solution.params, best.config, at_edge, pose, best.solution.prediction,
                                 best.solution.jacobian, cov, n_eff)
            if choice.rule == "wedge":  # the same fit as the wedge rule asked for
                best, cov, arrays = fit_wedge()
        else:
            choice = RuleChoice(rule, reason="asked for" if unplanned is None else
                                f"the {options.rule} rule was not used: {unplanned}")
    if log:
        log(f"rule {choice.rule}: {choice.reason}")
    sol, cfg = best.solution, best.config
    clusters = edge_clusters([s.profile_id for s in samples], len(sol.residuals))
    sun_free = None if fit_sun else _sun_free(sol, cfg, arrays, pose, options, float(used[0].sun_elevation_deg))
    solve_seconds = _time.perf_counter() - solve_start
    est = k_rho_with_errors(sol.params, cov)
    robust = k_rho_with_errors(sol.params, cluster_covariance(sol.residuals, sol.jacobian, clusters))
    # One number for the group: the root mean square of the photos' blurs (px).
    raw_blur = np.asarray(sol.params.raw_blur, dtype=np.float64)
    blur_px = float(np.sqrt(np.mean(np.maximum(raw_blur, 0.0)))) if float(cfg.fit_blur) else None
    penumbra_px, penumbra_iqr = penumbra_width_px(samples, sol.prediction)
    errors = combine_errors(est.range_k, est.rho, (est.range_stderr, est.rho_stderr),
                            (robust.range_stderr, robust.rho_stderr), penumbra_px)
    counts = sample_counts(samples, sol.prediction)
    sky_hidden, sun_cos = np.asarray(arrays.sky_hidden), np.asarray(arrays.sun_cos)
    evidence = FitEvidence(
        k=est.range_k, rho=est.rho, k_stderr_stat=errors.range_stderr_stat, rho_stderr_stat=errors.rho_stderr_stat,
        k_stderr_sys=errors.range_stderr_sys, rho_stderr_sys=errors.rho_stderr_sys, penumbra_px=penumbra_px,
        blur_px=blur_px, n_in_penumbra=counts.penumbra, n_in_umbra=counts.umbra,
        n_profiles=int(sum(s.n_profiles for s in samples)), converged=bool(sol.converged),
        range_k_max=options.range_k_max,
        photos=tuple(photos_evidence(samples, _photo_slices(samples), sol, est, errors, sun_cos, sky_hidden,
                                     fit_sun=fit_sun, fit_blur=bool(float(cfg.fit_blur)))),
        no_ramp_k=no_ramp_k(sol.prediction.u[:n_eff], est.range_k), sun_fitted=fit_sun, sun_free=sun_free,
        penumbra_px_per_k=penumbra_px_per_k(sol.prediction.u[:n_eff], sol.prediction.slope[:n_eff], est.range_k),
        photos_without_shadow=tuple(_split_reason(w) for w in no_shadow),
        receiver=getattr(used[0].receiver, "kind", "plane") if used[0].receiver is not None else "plane",
        remaining_step_se=remaining_step_se(sol.params, sol.residuals, sol.jacobian, errors.range_stderr_stat,
                                            errors.rho_stderr_stat),
        rule=choice.rule, rule_asked=options.rule, rule_unavailable=unplanned)
    estimate, verdict = judge_fit(evidence, GroupContext(photos_given=len(views)))
    plots = PlotData()
    if options.plots:
        plots = PlotData(
            tuple(profile_plot_data(samples, sol.prediction, est.rho, sky_hidden, sun_cos)),
            tuple(_overlay(model, pose, used[i], sol.params, cfg, samples[i]) for i in range(len(samples))
                  if options.overlays == "all" or (options.overlays == "first" and i == 0)))
    d = np.asarray(sol.params.sun_delta_deg) * float(cfg.fit_sun)
    registration = [v.reprojection_error_px for v in used if v.reprojection_error_px is not None]
    diagnostics = FitDiagnostics(
        rmse=float(np.sqrt(best.rss / n_eff)), n_profiles=evidence.n_profiles, n_samples=n_eff,
        converged=bool(sol.converged), profile=cfg.profile, rule=cfg.rule, rule_criterion=choice.criterion,
        blur_px=blur_px, penumbra_px=penumbra_px,
        penumbra_px_iqr=penumbra_iqr, reprojection_error_px=max(registration) if registration else None,
        seconds=_time.perf_counter() - start, solve_seconds=solve_seconds)
    sun = SunUsed(float(used[0].sun_azimuth_deg) + float(d[0]), float(used[0].sun_elevation_deg) + float(d[1]),
                  used[0].sun_source)
    return GroupResult(label, time_label, names, verdict, estimate, sun, diagnostics, plots, evidence=evidence)


def _sun_free(sol: Solution, cfg: FitConfig, arrays: GroupArrays, pose: Pose, options: FitOptions,
              elevation_deg: float) -> SunFree:
    """The solve repeated from its solution on the same samples with the sun free (the compiled solver
    takes the switch as an array: no new program), as evidence of whether the shadows want another sun,
    and whether k and rho follow it."""
    free = FitConfig.make(cfg.profile, bool(float(cfg.fit_blur)), True, float(cfg.huber_delta), cfg.rule)
    s = _to_numpy(_solve(sol.params, (arrays, pose, free), options.max_steps, jnp.zeros(9), jnp.asarray(False)))
    d = np.asarray(s.params.sun_delta_deg, dtype=np.float64)
    return SunFree(float(d[0]), float(d[1]), _k_np(s.params.raw_k), _rho_np(s.params.raw_rho), elevation_deg)


def _split_reason(warning: str) -> tuple[str, str]:
    """("photo", "reason") from a "photo: reason" line of ``sample_views``."""
    photo, _, reason = warning.partition(": ")
    return photo, reason
