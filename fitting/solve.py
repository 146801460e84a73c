"""Fitting one time of day: samples from each photo, a coarse start, optimistix least squares.

Photos of one group share k, rho (and a sun correction when the sun is
fitted); each keeps its own lit levels (paper and ground) and a linear
brightness gradient (exposure, vignetting). Optional terms, the camera blur
and the penumbra profile, are chosen by BIC. Uncertainties come from the
Jacobian at the solution, scaled by the residual variance.
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

from softshadow import GroundGrid, Pose, SoftShadowModel, Sun, bucket_size, concatenate_plans

from .model import (K_SCALE, FitConfig, GroupArrays, angular_pixel_gradient, predict, raw_from_k,
                    raw_from_rho, residuals)
from .overlay import fitted_alpha_image
from .results import GroupResult, OverlayPlotData, ProfilePlotData
from .samples import NoShadowInView, PhotoSamples, select_samples
from .views import PhotoView

__all__ = ["FitOptions", "fit_group"]

#: Levenberg-Marquardt tolerances (relative, absolute) on the parameters and on each residual
#: (residuals are relative to the lit level, whose noise is ~1e-2: 1e-4 is 1 % of it).
LM_RTOL, LM_ATOL = 1e-4, 1e-4



@dataclasses.dataclass
class FitOptions:
    """Choices of the fit. profiles / blur: candidates compared by BIC.

    The default profile is ``disk``: the sun is a disk, and with it k reads tan(sun radius),
    the truth convention of CONVENTIONS and the Mitsuba renders. ("linear", "disk") lets BIC
    choose; a linear ramp fitted to a real sun reads about 0.854 of that k.
    """

    profiles: tuple[str, ...] = ("disk",)
    blur: tuple[bool, ...] = (False, True)
    rule: str = "edge"
    range_k_max: float = 0.03
    max_samples_per_photo: int = 1300  # three photos fill a 4,096 bucket
    robust: bool = True
    max_steps: int = 60
    seed: int = 0
    sky_occlusion: bool = True  # model the sky the object hides from each sample (fitting.sky)
    plots: bool = True
    overlays: str = "first"  # overlay plots for the "first" photo of each group, or "all"
    verbose: bool = False


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
                                        else np.zeros(len(s.observed)) for s in samples]))))


def _initial_params(samples: list[PhotoSamples], fit_sun: bool) -> tuple[dict, float]:
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
    params = {"raw_k": f64(0.0), "raw_rho": f64(raw_from_rho(rho0)), "log_level": f64(log_level),
              "gradient": f64(np.zeros((len(samples), 2))), "raw_blur": f64(0.0),
              "sun_delta_deg": f64(np.zeros(2))}
    return params, rho0


class Trial(NamedTuple):
    """One solve: its BIC, solution, convergence, configuration, residual sum of squares,
    residuals (n,), Jacobian (n, p) and ``predict``'s outputs at the solution."""

    bic: float
    value: dict
    converged: bool
    config: FitConfig
    rss: float
    residuals: np.ndarray
    jac: np.ndarray
    diagnostics: tuple


def _bic(rss: float, n: int, n_free: int) -> float:
    return n * np.log(max(rss, 1e-300) / n) + n_free * np.log(n)


def _n_free(config: FitConfig, n_photos: int) -> int:
    """Parameters a configuration really fits (switched-off terms do not count)."""
    return 2 + 4 * n_photos + int(float(config.fit_blur)) + 2 * int(float(config.fit_sun))


def _k_np(raw) -> float:
    """k from raw_k in NumPy (post-processing stays out of JAX's eager dispatch)."""
    return float(K_SCALE * np.logaddexp(0.0, float(raw)))


def _rho_np(raw) -> float:
    return float(1.0 / (1.0 + np.exp(-float(raw))))


def _prepare(params: dict, raw_ks, group: GroupArrays, pose: Pose, config: FitConfig):
    """The samples' |dT/dpixel| (n,) and the raw_k (of the grid raw_ks) with the least plain
    sum of squares, blur and sun switched off and the other parameters fixed: the start."""
    grad_t_pixel = angular_pixel_gradient(group, pose, 0.01, config.rule)
    zero = jnp.zeros_like(config.fit_blur)
    coarse = (dataclasses.replace(group, grad_t_pixel=grad_t_pixel), pose,
              dataclasses.replace(config, fit_blur=zero, fit_sun=zero, huber_delta=zero))
    losses = jax.vmap(lambda rk: jnp.sum(residuals(dict(params, raw_k=rk), coarse) ** 2))(raw_ks)
    return grad_t_pixel, raw_ks[jnp.argmin(losses)]


@eqx.filter_jit
def _solve(params: dict, args, max_steps: int, start_raw_ks, prepare):
    """Levenberg-Marquardt from ``params``. Returns the solution, whether it converged, the
    number of steps, and at the solution the residuals (n,), their Jacobian (n, p) (flattened
    parameters, see ``_flat_index``), ``predict``'s outputs, and the samples' |dT/dpixel|.

    With ``prepare`` true (a traced switch, so one compiled program serves every call), the
    group's first solve: |dT/dpixel| is computed and raw_k starts at the best value of the
    grid ``start_raw_ks`` (m,) (``_prepare``). The Jacobian is the solver's own
    linearisation at its last accepted point, so the covariance costs no second pass."""
    group, pose, config = args
    grad_t_pixel, raw_k = jax.lax.cond(
        prepare, lambda: _prepare(params, start_raw_ks, group, pose, config),
        lambda: (group.grad_t_pixel, params["raw_k"]))
    group = dataclasses.replace(group, grad_t_pixel=grad_t_pixel)
    params = dict(params, raw_k=raw_k)
    args = (group, pose, config)
    solver = optx.LevenbergMarquardt(rtol=LM_RTOL, atol=LM_ATOL)
    sol = optx.least_squares(residuals, solver, params, args=args, max_steps=max_steps, throw=False)
    f_info = sol.state.f_info
    return (sol.value, sol.result == optx.RESULTS.successful, sol.stats["num_steps"],
            f_info.residual, f_info.jac.as_matrix(), predict(sol.value, group, pose, config),
            group.grad_t_pixel)


def _covariance(r: np.ndarray, jac: np.ndarray, n_eff: int):
    """Parameter covariance (p, p): (J^T J)^+ scaled by the residual variance s2; also s2."""
    dof = max(n_eff - jac.shape[1], 1)
    s2 = float(r @ r) / dof
    return np.linalg.pinv(jac.T @ jac, rcond=1e-12) * s2, s2


def _flat_index(params: dict) -> dict[str, int]:
    """Offset of each parameter in the flattened vector (ravel_pytree sorts a dict's keys)."""
    names = sorted(params)
    offsets = np.cumsum([0] + [np.size(params[k]) for k in names])
    return {k: int(offsets[i]) for i, k in enumerate(names)}


def _overlay(model: SoftShadowModel, pose: Pose, view: PhotoView, value: dict, cfg: FitConfig,
             s: PhotoSamples, max_side: int = 480) -> OverlayPlotData:
    """The fitted alpha over a downsampled copy of the photo, for the overlay plot."""
    import cv2
    h, w = view.shape
    f = min(1.0, max_side / max(h, w))
    sw, sh = max(int(round(w * f)), 1), max(int(round(h * f)), 1)
    small = cv2.resize(view.gray.astype(np.float32), (sw, sh), interpolation=cv2.INTER_AREA)
    d = np.asarray(value["sun_delta_deg"]) * float(cfg.fit_sun)
    sun = Sun(view.sun_azimuth_deg + d[0], view.sun_elevation_deg + d[1])
    if view.grid is not None:
        g = view.grid
        p = g.pixel_m * w / sw
        small_view = GroundGrid(p, (g.origin_m[0] + (p - g.pixel_m) / 2,
                                    g.origin_m[1] - (p - g.pixel_m) / 2), sw, sh)
    else:
        small_view = view.camera.with_size(sw, sh)
    alpha = fitted_alpha_image(model.with_options(profile=cfg.profile), pose, sun,
                               _k_np(value["raw_k"]), small_view)
    return OverlayPlotData(view.name, small, alpha, s.uv * f)


def fit_group(model: SoftShadowModel, pose: Pose, views: list[PhotoView], label: str,
              time_label: str | None, options: FitOptions | None = None) -> GroupResult:
    """Fit k and rho shared by ``views`` (one time of day). Never raises for bad data:
    failures come back as a GroupResult with ``error`` set."""
    options = options or FitOptions()
    start = _time.perf_counter()
    result = GroupResult(label=label, time=time_label, photos=[v.name for v in views])
    samples, used = [], []
    for i, view in enumerate(views):
        try:
            samples.append(select_samples(model, pose, view, options.range_k_max,
                                          max_samples=options.max_samples_per_photo, seed=options.seed + i,
                                          sky_occlusion=options.sky_occlusion))
            used.append(view)
        except NoShadowInView as exc:
            result.warnings.append(f"{view.name}: {exc}")
    if not samples:
        result.error = "no shadow in view: " + "; ".join(result.warnings)
        result.seconds = _time.perf_counter() - start
        return result
    fit_sun = any(v.sun_source == "fitted" for v in used)
    solve_start = _time.perf_counter()
    arrays = _group_arrays(samples, used)
    n_eff = sum(len(s.observed) for s in samples)
    base, rho0 = _initial_params(samples, fit_sun)
    # A plain least-squares pass, from the best k of a coarse log grid (the loss is flat where
    # the band misses the penumbra), sets the noise scale of the robust loss used after it.
    blur_first = True in options.blur
    plain = FitConfig.make(options.profiles[0], blur_first, fit_sun, 0.0, options.rule)
    grid = jnp.asarray(raw_from_k(np.geomspace(5e-4, options.range_k_max, 9)))
    start_value, _, _, r, _, _, grad_t_pixel = _solve(base, (arrays, pose, plain), options.max_steps,
                                                      grid, jnp.asarray(True))
    arrays = dataclasses.replace(arrays, grad_t_pixel=grad_t_pixel)
    r = np.asarray(r)
    sigma = 1.4826 * np.median(np.abs(r[np.abs(r) > 0])) if np.any(r) else 1e-3
    delta = float(max(3.0 * sigma, 1e-6)) if options.robust else 0.0

    def run(profile, blur, init):
        cfg = FitConfig.make(profile, blur, fit_sun, delta, options.rule)
        value, ok, steps, r, jac, diag, _ = _solve(init, (arrays, pose, cfg), options.max_steps,
                                                   grid, jnp.asarray(False))
        r, jac = np.asarray(r), np.asarray(jac)
        rss = float(r @ r)
        bic = _bic(rss, n_eff, _n_free(cfg, len(samples)))
        if options.verbose:
            print(f"  {label}: profile {profile} blur {blur}: {int(steps)} steps, ok {bool(ok)}, "
                  f"BIC {bic:.1f}")
        return Trial(bic, value, bool(ok), cfg, rss, r, jac, diag)

    # Profiles are compared with blur free, each solve starting from the previous solution.
    best = None
    for profile in options.profiles:
        trial = run(profile, blur_first, start_value if best is None else best.value)
        if best is None or trial.bic < best.bic:
            best = trial
    cov, s2 = _covariance(best.residuals, best.jac, n_eff)
    if blur_first and False in options.blur:
        # BIC without blur, from the fit with it: the nested model's residual sum of squares is
        # RSS + b^2 / [(J^T J)^-1]_bb to second order (exact for a linear model), so a solve
        # without blur is needed only when BIC prefers it.
        i_blur = _flat_index(best.value)["raw_blur"]
        inv_jtj = cov[i_blur, i_blur] / max(s2, 1e-300)
        rss_no_blur = best.rss + float(best.value["raw_blur"]) ** 2 / max(inv_jtj, 1e-300)
        no_blur_cfg = FitConfig.make(best.config.profile, False, fit_sun, delta, options.rule)
        bic_no_blur = _bic(rss_no_blur, n_eff, _n_free(no_blur_cfg, len(samples)))
        if options.verbose:
            print(f"  {label}: BIC without blur, to second order: {bic_no_blur:.1f}")
        # Worth a solve only when the estimate wins by more than 2 (a BIC difference under 2
        # is not evidence either way; the blur fit contains no blur as blur ~ 0); the solve is
        # kept only if its real BIC is lower too.
        if bic_no_blur < best.bic - 2.0:
            trial = run(best.config.profile, False,
                        dict(best.value, raw_blur=jnp.zeros_like(best.value["raw_blur"])))
            if trial.bic < best.bic:
                best = trial
                cov, s2 = _covariance(best.residuals, best.jac, n_eff)
    value, ok, cfg, rss = best.value, best.converged, best.config, best.rss
    result.solve_seconds = _time.perf_counter() - solve_start
    # Standard errors through the reparameterisation.
    idx = _flat_index(value)
    k = _k_np(value["raw_k"])
    rho = _rho_np(value["raw_rho"])
    dk = K_SCALE * _rho_np(value["raw_k"])  # d softplus = sigmoid
    drho = rho * (1 - rho)
    var_k = cov[idx["raw_k"], idx["raw_k"]] * dk**2
    var_rho = cov[idx["raw_rho"], idx["raw_rho"]] * drho**2
    result.range_k = k
    result.rho = rho
    result.range_stderr = float(np.sqrt(max(var_k, 0)))
    result.rho_stderr = float(np.sqrt(max(var_rho, 0)))
    result.profile = cfg.profile
    result.blur_px = float(np.sqrt(max(float(value["raw_blur"]), 0.0))) if float(cfg.fit_blur) else None
    result.rmse = float(np.sqrt(rss / n_eff))
    result.converged = bool(ok)
    result.n_samples = n_eff
    result.n_profiles = int(sum(s.n_profiles for s in samples))
    result.reprojection_error_px = (max(v.reprojection_error_px for v in used
                                        if v.reprojection_error_px is not None)
                                    if any(v.reprojection_error_px is not None for v in used) else None)
    az0, el0 = float(used[0].sun_azimuth_deg), float(used[0].sun_elevation_deg)
    if float(cfg.fit_sun):
        d = np.asarray(value["sun_delta_deg"])
        az0, el0 = az0 + d[0], el0 + d[1]
    result.sun_azimuth_deg, result.sun_elevation_deg = az0, el0
    result.sun_source = used[0].sun_source
    # Penumbra width in pixels at the solution; identifiability.
    pred, alpha, u, slope = (np.asarray(x) for x in best.diagnostics)
    sky_hidden = np.asarray(arrays.sky_hidden)
    widths = []
    start_i = 0
    for i, s in enumerate(samples):
        sl = slice(start_i, start_i + len(s.observed))
        start_i += len(s.observed)
        in_pen = np.abs(u[sl]) < 1
        if in_pen.any():
            widths.append(2.0 / np.maximum(slope[sl][in_pen], 1e-12))
        if options.plots:
            lvl = pred[sl] / np.maximum(1 - alpha[sl] * (1 - rho) - rho * sky_hidden[sl], 1e-9)
            dist = np.where(slope[sl] > 0, u[sl] / np.maximum(slope[sl], 1e-12), np.nan)
            result.plot_profiles.append(ProfilePlotData(
                s.name, dist, s.observed / lvl, pred[sl] / lvl, s.profile_id))
            if options.overlays == "all" or i == 0:
                result.plot_overlays.append(_overlay(model, pose, used[i], value, cfg, s))
    if widths:
        w = np.concatenate(widths)
        result.penumbra_px = float(np.median(w))
        q75, q25 = np.percentile(w, [75, 25])
        result.penumbra_px_iqr = float(q75 - q25)
    # Not identifiable: the penumbra is well below a pixel, or k is lost in its own noise.
    if (result.penumbra_px is None or result.penumbra_px < 0.8
            or result.range_stderr > 0.5 * max(k, 1e-12)):
        result.identifiable = False
        upper = k + 2.0 * result.range_stderr
        if result.penumbra_px:
            upper = max(upper, k * 1.0 / max(result.penumbra_px, 1e-9))
        result.range_k = float(upper)
        result.warnings.append("range not identifiable: the penumbra is narrower than the "
                               "resolution; range_k is an upper bound")
    if not ok:
        result.warnings.append("the solver stopped before converging")
    result.seconds = _time.perf_counter() - start
    return result
