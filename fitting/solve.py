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

from .model import (FitConfig, PhotoArrays, angular_pixel_gradient, k_from_raw, predict_photo,
                    raw_from_k, raw_from_rho, residuals, rho_from_raw)
from .results import GroupResult, OverlayPlotData, ProfilePlotData
from .samples import NoShadowInView, PhotoSamples, select_samples
from .views import PhotoView

__all__ = ["FitOptions", "fit_group"]


@dataclasses.dataclass
class FitOptions:
    """Choices of the fit. profiles / blur: candidates compared by BIC."""

    profiles: tuple[str, ...] = ("linear", "disk")
    blur: tuple[bool, ...] = (False, True)
    rule: str = "edge"
    range_k_max: float = 0.03
    max_samples_per_photo: int = 4000
    robust: bool = True
    max_steps: int = 50
    seed: int = 0
    plots: bool = True
    verbose: bool = False


def _to_arrays(s: PhotoSamples, view: PhotoView) -> PhotoArrays:
    n = len(s.observed)
    size = s.plan.edge_id.shape[0]
    pad = lambda x, fill=0.0: np.concatenate([x, np.full((size - n,) + x.shape[1:], fill, dtype=x.dtype)])
    lit = s.observed[np.asarray(s.plan.hard)[:n] < 0.5]
    scale = float(np.percentile(lit, 75)) if len(lit) else float(np.percentile(s.observed, 90))
    return PhotoArrays(
        ground=jnp.asarray(pad(s.ground)), jac=jnp.asarray(pad(s.jac)),
        observed=jnp.asarray(pad(s.observed)), weight=jnp.asarray(pad(np.ones(n))),
        albedo_class=jnp.asarray(pad(s.albedo_class.astype(np.int32), 0)),
        uv_norm=jnp.asarray(pad(s.uv_norm)), plan=s.plan,
        sun_azimuth_deg=jnp.asarray(float(view.sun_azimuth_deg)),
        sun_elevation_deg=jnp.asarray(float(view.sun_elevation_deg)),
        scale=jnp.asarray(max(scale, 1e-9)), grad_t_pixel=jnp.zeros(size))


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
              "raw_blur": jnp.asarray(0.5), "sun_delta_deg": jnp.zeros(2)}
    return params, rho0


def _n_free(config: FitConfig, n_photos: int) -> int:
    """Parameters a configuration really fits (switched-off terms do not count)."""
    return 2 + 4 * n_photos + int(float(config.fit_blur)) + 2 * int(float(config.fit_sun))


@jax.jit
def _sum_sq(params, args):
    return jnp.sum(residuals(params, args) ** 2)


def _solve(params: dict, args, max_steps: int):
    solver = optx.LevenbergMarquardt(rtol=1e-6, atol=1e-8)
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
    arrays = tuple(_to_arrays(s, v) for s, v in zip(samples, used))
    arrays = tuple(dataclasses.replace(a, grad_t_pixel=angular_pixel_gradient(
        a, pose, Sun(a.sun_azimuth_deg, a.sun_elevation_deg), 0.01, options.rule)) for a in arrays)
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
    best = None
    for profile in options.profiles:
        for blur in options.blur:
            cfg = FitConfig.make(profile, blur, fit_sun, delta, options.rule)
            args = (arrays, pose, cfg)
            value, ok, steps = _solve(start_value, args, options.max_steps)
            if options.verbose:
                print(f"  {label}: profile {profile} blur {blur}: {int(steps)} steps, ok {bool(ok)}")
            rss = float(_sum_sq(value, args))
            n_par = _n_free(cfg, len(arrays))
            bic = n_eff * np.log(max(rss, 1e-300) / n_eff) + n_par * np.log(n_eff)
            if best is None or bic < best[0]:
                best = (bic, value, ok, cfg, rss)
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
    result.blur_px = float(value["raw_blur"]) ** 2 if float(cfg.fit_blur) else None
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
    widths = []
    for i, (s, photo) in enumerate(zip(samples, arrays)):
        pred, alpha = predict_photo(value, i, photo, pose, cfg)
        from .model import _coordinate_and_pixel_gradient
        sun = Sun(photo.sun_azimuth_deg + cfg.fit_sun * value["sun_delta_deg"][0],
                  photo.sun_elevation_deg + cfg.fit_sun * value["sun_delta_deg"][1])
        u, gpix = _coordinate_and_pixel_gradient(photo, pose, sun, k, cfg.rule)
        n = len(s.observed)
        u, gpix = np.asarray(u)[:n], np.asarray(gpix)[:n]
        slope = np.linalg.norm(gpix, axis=1)
        in_pen = np.abs(u) < 1
        if in_pen.any():
            widths.append(2.0 / np.maximum(slope[in_pen], 1e-12))
        if options.plots:
            lvl = np.asarray(pred)[:n] / np.maximum(1 - np.asarray(alpha)[:n] * (1 - rho), 1e-9)
            dist = np.where(slope > 0, u / np.maximum(slope, 1e-12), np.sign(u) * 1e3)
            result.plot_profiles.append(ProfilePlotData(
                s.name, np.clip(dist, -1e3, 1e3), s.observed / lvl, np.asarray(pred)[:n] / lvl,
                s.profile_id))
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
