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

import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx
from jax.flatten_util import ravel_pytree

from softshadow.params import Pose
from softshadow.plan import bucket_size
from softshadow.render import SoftShadowModel

from softshadow.params import Sun

from softshadow.plan import concatenate_plans

from .model import (FitConfig, GroupArrays, angular_pixel_gradient, k_from_raw, predict, raw_from_k,
                    raw_from_rho, residuals, rho_from_raw)
from .results import GroupResult, OverlayPlotData, ProfilePlotData
from .samples import NoShadowInView, PhotoSamples, select_samples
from .views import PhotoView

__all__ = ["FitOptions", "fit_group"]



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
    plots: bool = True
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
        scale=jnp.asarray(scales), grad_t_pixel=jnp.zeros(size))


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
    params = {"raw_k": jnp.asarray(0.0), "raw_rho": jnp.asarray(float(raw_from_rho(rho0))),
              "log_level": jnp.asarray(log_level), "gradient": jnp.zeros((len(samples), 2)),
              "raw_blur": jnp.asarray(0.0), "sun_delta_deg": jnp.zeros(2)}
    return params, rho0


def _n_free(config: FitConfig, n_photos: int) -> int:
    """Parameters a configuration really fits (switched-off terms do not count)."""
    return 2 + 4 * n_photos + int(float(config.fit_blur)) + 2 * int(float(config.fit_sun))


@jax.jit
def _sum_sq(params, args):
    return jnp.sum(residuals(params, args) ** 2)


def _solve(params: dict, args, max_steps: int):
    solver = optx.LevenbergMarquardt(rtol=1e-5, atol=1e-6)
    sol = optx.least_squares(residuals, solver, params, args=args, max_steps=max_steps, throw=False)
    return sol.value, sol.result == optx.RESULTS.successful, sol.stats["num_steps"]


def _covariance(params: dict, args, n_eff: int):
    flat, unravel = ravel_pytree(params)
    fn = lambda x: residuals(unravel(x), args)
    jac = np.asarray(jax.jacfwd(fn)(flat))
    r = np.asarray(fn(flat))
    dof = max(n_eff - len(flat), 1)
    s2 = float(r @ r) / dof
    jtj = jac.T @ jac
    cov = np.linalg.pinv(jtj, rcond=1e-12) * s2
    return cov, unravel, flat, s2


def _overlay(model: SoftShadowModel, pose: Pose, view: PhotoView, value: dict, cfg: FitConfig,
             s: PhotoSamples, max_side: int = 480) -> OverlayPlotData:
    """The fitted alpha over a downsampled copy of the photo, for the overlay plot."""
    import cv2
    from softshadow.params import ShadowParams
    h, w = view.shape
    f = min(1.0, max_side / max(h, w))
    sw, sh = max(int(round(w * f)), 1), max(int(round(h * f)), 1)
    small = cv2.resize(view.gray.astype(np.float32), (sw, sh), interpolation=cv2.INTER_AREA)
    d = np.asarray(value["sun_delta_deg"]) * float(cfg.fit_sun)
    sun = Sun(view.sun_azimuth_deg + d[0], view.sun_elevation_deg + d[1])
    params = ShadowParams(float(k_from_raw(value["raw_k"])), 0.0)
    m = model.with_options(profile=cfg.profile)
    if view.grid is not None:
        from softshadow.camera import GroundGrid
        g = view.grid
        p = g.pixel_m * w / sw
        grid = GroundGrid(p, (g.origin_m[0] + (p - g.pixel_m) / 2, g.origin_m[1] - (p - g.pixel_m) / 2), sw, sh)
        alpha = 1.0 - np.asarray(m.ground_map(params, sun, pose, grid))
    else:
        render = m.camera_image(params, sun, pose, view.camera.with_size(sw, sh))
        alpha = 1.0 - np.asarray(render.shading)
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
                                          max_samples=options.max_samples_per_photo, seed=options.seed + i))
            used.append(view)
        except NoShadowInView as exc:
            result.warnings.append(f"{view.name}: {exc}")
    if not samples:
        result.error = "no shadow in view: " + "; ".join(result.warnings)
        result.seconds = _time.perf_counter() - start
        return result
    fit_sun = any(v.sun_source == "fitted" for v in used)
    arrays = _group_arrays(samples, used)
    arrays = dataclasses.replace(arrays, grad_t_pixel=angular_pixel_gradient(arrays, pose, 0.01,
                                                                             options.rule))
    n_eff = sum(len(s.observed) for s in samples)
    base, rho0 = _initial_params(samples, fit_sun)

    # Coarse start for k on a log grid (the loss is flat where the band misses the penumbra).
    coarse_cfg = FitConfig.make(options.profiles[0], rule=options.rule)
    grid = np.geomspace(5e-4, options.range_k_max, 9)
    losses = []
    for k in grid:
        p = dict(base, raw_k=jnp.asarray(float(raw_from_k(k))))
        losses.append(float(_sum_sq(p, (arrays, pose, coarse_cfg))))
    base["raw_k"] = jnp.asarray(float(raw_from_k(grid[int(np.argmin(losses))])))

    # A plain least-squares pass sets the noise scale of the robust loss used after it.
    plain = FitConfig.make(options.profiles[0], False, fit_sun, 0.0, options.rule)
    start_value, _, _ = _solve(base, (arrays, pose, plain), options.max_steps)
    r = np.asarray(residuals(start_value, (arrays, pose, plain)))
    sigma = 1.4826 * np.median(np.abs(r[np.abs(r) > 0])) if np.any(r) else 1e-3
    delta = float(max(3.0 * sigma, 1e-6)) if options.robust else 0.0
    # Profiles are compared with blur free; then blur is kept only if BIC says so. Each solve
    # starts from the previous solution, so the later ones take a few steps.
    def run(profile, blur, init):
        cfg = FitConfig.make(profile, blur, fit_sun, delta, options.rule)
        args = (arrays, pose, cfg)
        value, ok, steps = _solve(init, args, options.max_steps)
        rss = float(_sum_sq(value, args))
        bic = n_eff * np.log(max(rss, 1e-300) / n_eff) + _n_free(cfg, len(samples)) * np.log(n_eff)
        if options.verbose:
            print(f"  {label}: profile {profile} blur {blur}: {int(steps)} steps, ok {bool(ok)}, "
                  f"BIC {bic:.1f}")
        return bic, value, ok, cfg, rss

    blur_first = True in options.blur
    best = None
    for profile in options.profiles:
        trial = run(profile, blur_first, start_value if best is None else best[1])
        if best is None or trial[0] < best[0]:
            best = trial
    if blur_first and False in options.blur:
        trial = run(best[3].profile, False, best[1])
        if trial[0] < best[0]:
            best = trial
    bic, value, ok, cfg, rss = best
    args = (arrays, pose, cfg)
    cov, unravel, flat, s2 = _covariance(value, args, n_eff)
    # Standard errors through the reparameterisation.
    names = list(value.keys())
    offsets = np.cumsum([0] + [np.size(value[k]) for k in names])
    idx = {k: offsets[i] for i, k in enumerate(names)}
    k = float(k_from_raw(value["raw_k"]))
    rho = float(rho_from_raw(value["raw_rho"]))
    dk = float(jax.grad(k_from_raw)(value["raw_k"]))
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
    pred, alpha, u, slope = (np.asarray(x) for x in predict(value, arrays, pose, cfg))
    widths = []
    start_i = 0
    for i, s in enumerate(samples):
        sl = slice(start_i, start_i + len(s.observed))
        start_i += len(s.observed)
        in_pen = np.abs(u[sl]) < 1
        if in_pen.any():
            widths.append(2.0 / np.maximum(slope[sl][in_pen], 1e-12))
        if options.plots:
            lvl = pred[sl] / np.maximum(1 - alpha[sl] * (1 - rho), 1e-9)
            dist = np.where(slope[sl] > 0, u[sl] / np.maximum(slope[sl], 1e-12), np.nan)
            result.plot_profiles.append(ProfilePlotData(
                s.name, dist, s.observed / lvl, pred[sl] / lvl, s.profile_id))
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
