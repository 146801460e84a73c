"""Shadow brightness and penumbra width from one photo alone, across detected shadow edges.

Used where there is no scene description (no scene.toml, or no mesh): a photo
then supports only what its shadow edges show. The log of a linear image is
log I = log albedo + log E, so a shadow edge on one surface is a step of
log rho whatever the albedo texture. Each profile across a candidate edge is
fitted with

    log I(s) = a + b (s - s0) + log(1 - alpha(s) (1 - rho)),
    alpha(s) = clip(1/2 - (s - s0) / w, 0, 1),

s the signed distance (px) along the edge normal towards the lit side, s0 the
ramp centre, w the full width of the linear ramp (alpha from 1 to 0) and b a
local shading slope (with a weak prior); alpha is convolved with the known
blur of the bilinear resampling. Profiles that do not look like a shadow edge
on a single surface are rejected, the rest are combined robustly (median of
the dominant log-rho mode). See docs/edge_measure.md.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np
from scipy import optimize, special, stats

from fitting.edge_detect import (MIN_CHAIN_PX, LogImage, detect_edge_candidates, high_pass_log, log_image, max_half_span_inside,
                                 sample_profiles, sample_strips, to_work_scale)
from fitting.ground_region import ground_region
from fitting.shadow_cues import MODE_WINDOW_LOG, bluer_umbrae, mode_of_log_rho, reliability

__all__ = ["EdgeMeasurement", "EdgeProfile", "RampFit", "measure_shadow_edges", "fit_edge_profile", "ramp_alpha",
           "ramp_log_model"]

NO_EDGE_REASON = "no shadow edge found"

STEP_PX = 0.5              # sample spacing along a profile
STRIP_HALF_WIDTH_PX = 3    # each sample averages 7 lines 1 px apart along the edge
RHO_MAX = 0.9              # a step shallower than this is not treated as a shadow
RHO_MIN = 0.005
MIN_HALF_SPAN_PX = 8.0
MIN_PLATEAU_PX = 3.0       # flat ground needed on each side beyond the ramp ...
PLATEAU_PER_WIDTH = 0.5    # ... and at least this many ramp widths
PLATEAU_EXTRA_PX = 8.0     # the second pass spans w (0.5 + PLATEAU_PER_WIDTH) + this on each side
TEXTURE_SIGMA_PX = 1.0     # high-pass scale of the same-surface texture test
SMOOTH_TEXTURE_LOG = 3e-3  # texture below this (log units) on both sides: too smooth to compare
MAX_RESIDUAL_PER_STEP = 0.2    # rms fit residual / |log rho|: above it the profile holds more than one step
MAX_SLOPE_STEP_FRACTION = 0.5  # |b| * (span) / |log rho|: larger means shading or another edge dominates
# Same-surface test on the fine log texture, dark side over lit side. Low bound:
# diffuse sky light in the umbra flattens relief texture (0.2-0.9 measured on
# sunlit asphalt, DSC_0569). High bound: times 1/sqrt(rho), the growth of shot
# noise on the darker side.
TEXTURE_RATIO_LOW = 0.15
TEXTURE_RATIO_HIGH = 2.5
# |log step in a channel - log step of the channel sum|. Skylit umbrae are
# bluer: shadow edges on DSC_0569 gave -0.45 (R), +0.35 (B), at most 0.67;
# yellow paint on asphalt gave 0.83-1.3 in blue.
COLOUR_TOL_LOG = 0.75
NORMAL_SHIFT_MAX_PX = 4.0  # search range of a strip line's ramp shift when straightening the normal
# Edge bend over +-TURN_BASE_PX (5 px) along the edge: more is a corner, where a
# strip mixes two edge directions (widths within 4 px of a vertex read 20-50 %
# high). 35 deg keeps circles down to a radius of about 16 px.
MAX_TURN_DEG = 35.0
MIN_PROFILES = 5           # fewer shadow-like profiles than this is not a measurement
# Edges are measured on the photo box-averaged to at most this longer side.
# Why: on a 4000x3000 photo a long shadow's penumbra spans 30-100 px, so its
# log gradient (log(1/rho) / w, about 0.02-0.05 per px) falls under Canny's
# thresholds while gravel at the detection scales clears them, and the first
# profile pass (3 sigma + 6 px) is narrower than the ramp: the shadow's
# profiles came out as "ramp not inside the profile" or "no darker side" and
# cloud edges and facades won. Averaging by f makes the ramp w / f px wide
# and averages the pebbles away; plateau ratios (rho) do not change.
WORK_MAX_SIDE_PX = 1024
# Canny chains shorter than this fraction of the working image's longer side
# are left out (and never shorter than edge_detect's MIN_CHAIN_PX): on gravel
# the pebbles' chains (20-60 px) took most of the profile budget, spread evenly
# over all chains, and left the shadow outline a few percent of it.
MIN_CHAIN_PER_SIDE = 0.05
NOT_GROUND_REASON = "not on the ground (sky, or above the horizon)"
BOOTSTRAP_RESAMPLES = 400
# Gaussian prior (log units per px) on the shading slope b. Free, b trades
# against rho whenever the plateaus are short (a texture tilt reads as a
# different step: per-profile rho scattered 3x more on synthetic paper and was
# biased by +0.004 to +0.008); this prior lets b absorb only a gradient the
# whole profile supports (vignetting, gentle shading are ~1e-4 per px).
SLOPE_SIGMA_PER_PX = 3e-4
# Profiles are read with bilinear interpolation, which blurs along the normal
# with a triangle kernel of variance 1/6 px^2 whatever the direction; the model
# includes it (as a Gaussian of that variance) so that w is the ramp's width
# in the image. Without it a 4 px ramp read 4.3 px (w^2 grows by 12 x 1/6 = 2).
SAMPLING_BLUR_PX = float(np.sqrt(1.0 / 6.0))


@dataclass(frozen=True)
class EdgeProfile:
    """One profile across a candidate edge, fitted, for plots and diagnostics.

    position_uv: (2,) pixel (u, v) of the fitted ramp centre s0.
    normal_uv: (2,) unit vector across the edge, from the shadow towards the lit side.
    rho: fitted lit-to-umbra ratio of this profile (linear).
    width_px: full width w of the fitted linear ramp (alpha 1 -> 0), along the normal, in pixels.
    residual: rms of the fit residual, in natural-log units.
    kept: True when the profile passed every shadow-edge test and the mode window.
    reject_reason: why it was not kept (None when kept).
    offsets_px: (S,) sample positions s along the normal, relative to position_uv.
    observed_log: (S,) log of the observed linear values (strip means).
    fitted_log: (S,) the fitted model at offsets_px.
    blue_shift_log: log step of blue minus log step of red across the edge
        (positive: the dark side is bluer, as a skylit umbra is); NaN without colour.
    """

    position_uv: np.ndarray
    normal_uv: np.ndarray
    rho: float
    width_px: float
    residual: float
    kept: bool
    reject_reason: str | None
    offsets_px: np.ndarray
    observed_log: np.ndarray
    fitted_log: np.ndarray
    blue_shift_log: float = float("nan")


@dataclass(frozen=True)
class EdgeMeasurement:
    """What one photo alone says about its shadow.

    rho: robust (median) shadow brightness over the kept profiles, linear ratio
        umbra / lit on the same surface; NaN when nothing was measured.
    rho_stderr: one-sigma uncertainty of that median (block bootstrap over
        profiles); not the spread of rho over the scene.
    penumbra_px: median full width w of the fitted linear ramp (alpha from 1 to
        0; 1.25 times its 10-90 % width) across the edge, in image pixels along
        the edge normal. The blur of this module's own resampling is modelled
        out; the camera's (pixel aperture, optics, demosaicing) is included.
    penumbra_px_iqr: interquartile range of the widths (px).
    penumbra_m: penumbra_px * pixel_m when pixel_m is given, else None.
    n_profiles: number of kept profiles.
    edges_found: False when no shadow edge could be measured.
    profiles: every fitted profile, kept or not (EdgeProfile).
    reason: why nothing was measured (None when edges_found).
    warnings: one-line reasons to doubt the result (``fitting.shadow_cues``):
        edges that disagree, too few profiles, profiles scattered over
        unrelated structures.
    reliable: False when there is any warning (the value is still given).
    """

    rho: float
    rho_stderr: float
    penumbra_px: float
    penumbra_px_iqr: float
    penumbra_m: float | None
    n_profiles: int
    edges_found: bool
    profiles: list[EdgeProfile]
    reason: str | None
    warnings: tuple[str, ...] = ()
    reliable: bool = True


def ramp_alpha(s: np.ndarray, s0: float, w: float, blur_px: float = 0.0) -> np.ndarray:
    """Linear ramp alpha(s) = clip(1/2 - (s - s0) / w, 0, 1), convolved with a Gaussian of std blur_px.

    With G(z) = E[max(z + e, 0)], e ~ N(0, blur^2), = z Phi(z / blur) + blur phi(z / blur),
    the blurred ramp is (G(w/2 - x) - G(-w/2 - x)) / w, x = s - s0 (closed form).
    """
    x = np.asarray(s, float) - s0
    if blur_px <= 0.0:
        return np.clip(0.5 - x / w, 0.0, 1.0)
    return (_expected_ramp(0.5 * w - x, blur_px) - _expected_ramp(-0.5 * w - x, blur_px)) / w


def ramp_log_model(s: np.ndarray, a: float, b: float, s0: float, w: float, rho: float,
                   blur_px: float = 0.0) -> np.ndarray:
    """log I(s) = a + b (s - s0) + log(1 - alpha(s) (1 - rho)), alpha the (blurred) linear ramp of ``ramp_alpha``."""
    return a + b * (np.asarray(s, float) - s0) + np.log1p(-ramp_alpha(s, s0, w, blur_px) * (1.0 - rho))


def _expected_ramp(z: np.ndarray, sigma: float) -> np.ndarray:
    t = z / sigma
    return z * special.ndtr(t) + sigma * np.exp(-0.5 * t * t) / np.sqrt(2.0 * np.pi)


@dataclass(frozen=True)
class RampFit:
    """Fitted ramp_log_model parameters, the rms residual (log units) and the model at the samples."""

    a: float
    b: float
    s0: float
    w: float
    rho: float
    residual_rms: float
    fitted: np.ndarray


def fit_edge_profile(s: np.ndarray, y: np.ndarray, max_width_px: float,
                     slope_sigma_per_px: float | None = SLOPE_SIGMA_PER_PX,
                     blur_px: float = SAMPLING_BLUR_PX) -> RampFit | None:
    """Robust least-squares fit of ``ramp_log_model`` to one log profile y(s) (s increasing towards lit).

    s: (S,) increasing sample offsets (px); y: (S,) log values. slope_sigma_per_px:
    std of the Gaussian prior on the slope b (None: free). blur_px: known
    Gaussian blur of the samples along s (default: the bilinear resampling's).

    Start from the plateaus (outer quarters of the span) and the extent of the
    20-80 % part of the step; soft-L1 loss at the profile's noise level so that
    a speck or a crack inside the span does not pull the fit. Returns None when
    the data show no darker side.
    """
    span = s[-1] - s[0]
    dark = y[s < s[0] + 0.25 * span]
    lit = y[s > s[-1] - 0.25 * span]
    a0 = float(np.median(lit))
    d0 = float(np.median(dark)) - a0
    if not d0 < 0:
        return None
    rho0 = float(np.clip(np.exp(d0), 0.02, 0.95))
    frac = (np.exp(y - a0) - rho0) / (1.0 - rho0)       # 1 - alpha, in linear units
    mid = (frac > 0.2) & (frac < 0.8)
    ds = s[1] - s[0]
    w0 = float(np.clip(mid.sum() * ds / 0.6, 1.0, max_width_px * 0.9))
    s00 = float(np.median(s[mid])) if mid.any() else 0.0
    s00 = float(np.clip(s00, s[0] + 0.3 * span, s[-1] - 0.3 * span))
    noise = max(_robust_std(np.diff(y)) / np.sqrt(2.0), 1e-3)

    prior = 0.0 if slope_sigma_per_px is None else noise / slope_sigma_per_px
    blur = max(blur_px, 1e-3)      # the closed form needs blur > 0; 1e-3 px is a sharp ramp

    def residual(p):
        return np.append(ramp_log_model(s, *p, blur_px=blur) - y, prior * p[1])

    def jacobian(p):
        a, b, s0, w, rho = p
        x = s - s0
        alpha = ramp_alpha(s, s0, w, blur)
        hi_edge = special.ndtr((0.5 * w - x) / blur)
        lo_edge = special.ndtr((-0.5 * w - x) / blur)
        dalpha_ds0 = (hi_edge - lo_edge) / w
        dalpha_dw = 0.5 * (hi_edge + lo_edge) / w - alpha / w
        g = 1.0 - alpha * (1.0 - rho)
        dm_dalpha = -(1.0 - rho) / g
        jac = np.zeros((s.size + 1, 5))
        jac[:-1, 0] = 1.0
        jac[:-1, 1] = x
        jac[:-1, 2] = -b + dm_dalpha * dalpha_ds0
        jac[:-1, 3] = dm_dalpha * dalpha_dw
        jac[:-1, 4] = alpha / g
        jac[-1, 1] = prior
        return jac

    lo = [-np.inf, -np.inf, s[0] + 0.2 * span, 0.3, RHO_MIN]
    hi = [np.inf, np.inf, s[-1] - 0.2 * span, max_width_px, 0.999]
    p0 = np.clip([a0, 0.0, s00, w0, rho0], np.add(lo, 1e-9), np.subtract(hi, 1e-9))
    sol = optimize.least_squares(residual, p0, jac=jacobian, bounds=(lo, hi), loss="soft_l1",
                                 f_scale=3.0 * noise, x_scale="jac", max_nfev=200)
    a, b, s0, w, rho = (float(v) for v in sol.x)
    fitted = ramp_log_model(s, a, b, s0, w, rho, blur_px=blur)
    return RampFit(a, b, s0, w, rho, float(np.sqrt(np.mean((fitted - y) ** 2))), fitted)


def measure_shadow_edges(linear_gray: np.ndarray, mask: np.ndarray | None = None, pixel_m: float | None = None,
                         max_profiles: int = 400, rng_seed: int = 0, *,
                         linear_rgb: np.ndarray | None = None,
                         saturation_level: float | None = None) -> EdgeMeasurement:
    """Measure the shadow brightness rho and the penumbra width across shadow edges in one photo.

    linear_gray: (H, W) float, linear radiometry (any scale; not display-encoded).
    mask: (H, W) bool, True = ignore these pixels (the object, a board, ...).
    pixel_m: ground size of one pixel (m), for ``penumbra_m``; only meaningful
        for a top-down image of a flat receiver.
    max_profiles: at most this many profiles are sampled and fitted.
    rng_seed: seeds the choice of profile positions and the bootstrap.
    linear_rgb: optional (H, W, 3) linear colour image of the same photo; when
        given, a profile is kept only if its dark/lit ratio is about the same in
        every channel (a shadow dims all channels alike, up to the bluer sky
        light in the umbra; painted lines and coloured objects do not).
    saturation_level: linear value at or above which a pixel (or, with
        linear_rgb, any of its channels) is clipped and ignored; pass 1.0 for
        images normalised from integer files (linearised 8-bit sRGB, 16-bit,
        RAW scaled to its white level). None: nothing is treated as clipped.

    Returns an EdgeMeasurement; "no shadow in view" is not an error
    (edges_found False, reason "no shadow edge found"). Raises ValueError for
    malformed input.
    """
    gray = _checked_gray(linear_gray)
    ignore = _checked_mask(mask, gray.shape)
    rgb = _checked_rgb(linear_rgb, gray.shape)
    if pixel_m is not None and not (np.isfinite(pixel_m) and pixel_m > 0):
        raise ValueError(f"pixel_m must be a positive number of metres, got {pixel_m!r}")
    if int(max_profiles) < 1:
        raise ValueError(f"max_profiles must be at least 1, got {max_profiles!r}")
    rng = np.random.default_rng(rng_seed)

    bad = np.zeros(gray.shape, bool) if ignore is None else ignore.copy()
    if rgb is not None:
        bad |= ~np.isfinite(rgb).all(axis=2)
    if saturation_level is not None:
        bad |= gray >= saturation_level
        if rgb is not None:
            bad |= (rgb >= saturation_level).any(axis=2)
    work = to_work_scale(gray, rgb, bad, WORK_MAX_SIDE_PX)
    img = log_image(work.gray, work.bad)
    if not img.valid.any():
        return _nothing("every pixel is masked, clipped or not finite", [])
    ground = ground_region(work.rgb, work.gray)
    # Candidates only where ground may be; profiles may still reach across (the
    # horizon margin keeps them off the sky).
    min_chain = max(MIN_CHAIN_PX, MIN_CHAIN_PER_SIDE * max(work.gray.shape))
    candidates = detect_edge_candidates(LogImage(img.log, img.valid & ground.ground), int(max_profiles), rng,
                                        min_chain_px=min_chain)
    if len(candidates) == 0:
        return _nothing(NO_EDGE_REASON, [])

    images = _Images(gray=work.gray, valid=img.valid, texture=high_pass_log(img, TEXTURE_SIGMA_PX), rgb=work.rgb)
    profiles = _fit_candidates(images, candidates)
    profiles = [p if not p.kept or ground.contains(p.position_uv)[0] else _with_reason(p, NOT_GROUND_REASON)
                for p in profiles]
    profiles = _prefer_bluer_umbrae(profiles)
    shadow_like_log_rho = np.log([p.rho for p in profiles if p.kept])
    profiles = _keep_dominant_mode(profiles)
    profiles = [_to_full_scale(p, work) for p in profiles]
    kept = [p for p in profiles if p.kept]
    if len(kept) < MIN_PROFILES:
        return _nothing(NO_EDGE_REASON, profiles)

    log_rho = np.log([p.rho for p in kept])
    widths = np.array([p.width_px for p in kept])
    positions = np.array([p.position_uv for p in kept])
    rho = float(np.exp(np.median(log_rho)))
    rho_stderr = _block_bootstrap_median_stderr(np.exp(log_rho), positions, rng)
    q25, q50, q75 = np.percentile(widths, [25, 50, 75])
    warnings, reliable = reliability(shadow_like_log_rho, positions, gray.shape, np.log(RHO_MIN))
    return EdgeMeasurement(rho=rho, rho_stderr=rho_stderr, penumbra_px=float(q50), penumbra_px_iqr=float(q75 - q25),
                           penumbra_m=None if pixel_m is None else float(q50 * pixel_m), n_profiles=len(kept),
                           edges_found=True, profiles=profiles, reason=None, warnings=tuple(warnings),
                           reliable=reliable)


@dataclass(frozen=True)
class _Images:
    """The arrays every profile is sampled from."""

    gray: np.ndarray            # (H, W) linear
    valid: np.ndarray           # (H, W) bool
    texture: np.ndarray         # (H, W) high-pass log (fine texture plus noise)
    rgb: np.ndarray | None      # (H, W, 3) linear, or None


def _fit_candidates(images: _Images, candidates) -> list[EdgeProfile]:
    """Sample, fit and screen every candidate (two passes: the second spans the fitted ramp)."""
    max_half = max(MIN_HALF_SPAN_PX, 0.25 * min(images.gray.shape))
    profiles: list[EdgeProfile] = []
    for point, normal, sigma, turn in zip(candidates.points_uv, candidates.normals_uv, candidates.sigma_px,
                                          candidates.turn_deg):
        if turn > MAX_TURN_DEG:
            profiles.append(_rejected(point, normal, f"edge bends {turn:.0f} deg within 10 px (a corner)"))
            continue
        room = max_half_span_inside(point, normal, images.gray.shape, STRIP_HALF_WIDTH_PX)
        half1 = min(3.0 * sigma + 6.0, max_half, room)
        first = _profile_fit(images, point, normal, half1)
        if isinstance(first, str):
            profiles.append(_rejected(point, normal, first))
            continue
        # Straighten the normal (the smoothed gradient leans near corners and in
        # texture), re-centre on the fitted ramp and span enough plateau beyond it.
        normal = _refined_normal(images, point, normal, first[1][-1], first[0])
        centre = point + first[0].s0 * normal
        room = max_half_span_inside(centre, normal, images.gray.shape, STRIP_HALF_WIDTH_PX)
        half2 = min(first[0].w * (0.5 + PLATEAU_PER_WIDTH) + PLATEAU_EXTRA_PX, max_half, room)
        second = _profile_fit(images, centre, normal, half2)
        if isinstance(second, str):
            profiles.append(_rejected(centre, normal, second))
            continue
        fit, s, y = second
        half2 = float(s[-1])
        reason, blue = _shadow_edge_test(images, centre, normal, half2, fit, s, y)
        profiles.append(EdgeProfile(position_uv=centre + fit.s0 * normal, normal_uv=normal, rho=fit.rho,
                                    width_px=fit.w, residual=fit.residual_rms, kept=reason is None,
                                    reject_reason=reason, offsets_px=s - fit.s0, observed_log=y,
                                    fitted_log=fit.fitted, blue_shift_log=blue))
    return profiles


def _refined_normal(images: _Images, point, normal, half_span_px: float, fit: RampFit) -> np.ndarray:
    """The edge normal corrected by the tilt of the ramp across the strip's lines.

    Each of the strip's 2 T + 1 lines is matched (least squares over a shift
    and an offset, so line-to-line albedo does not matter) to the fitted
    ramp; a straight line through the shifts against the lines' positions
    gives the edge's slope k relative to the tangent, and the normal becomes
    normalize(n - k t). With fewer than 4 usable lines the normal is kept.
    """
    grid = sample_strips(images.gray, point[None], normal[None], half_span_px, STEP_PX, STRIP_HALF_WIDTH_PX)[0]
    good = sample_strips(images.valid.astype(float), point[None], normal[None], half_span_px, STEP_PX,
                         STRIP_HALF_WIDTH_PX)[0] > 0.999
    lines = good.all(axis=0)                                                   # (T,)
    if lines.sum() < 4:
        return normal
    s = np.arange(grid.shape[0]) * STEP_PX - half_span_px
    logs = np.log(np.maximum(grid[:, lines], 1e-300)).T                        # (L, S)
    shifts = np.arange(-NORMAL_SHIFT_MAX_PX, NORMAL_SHIFT_MAX_PX + 1e-9, 0.1)
    templates = np.stack([ramp_log_model(s - d, fit.a, fit.b, fit.s0, fit.w, fit.rho, SAMPLING_BLUR_PX)
                          for d in shifts])                                     # (D, S)
    diff = logs[:, None, :] - templates[None, :, :]                            # (L, D, S)
    cost = diff.var(axis=2)                                                     # offset per line is free
    best = shifts[np.argmin(cost, axis=1)]                                      # (L,)
    t = np.arange(-STRIP_HALF_WIDTH_PX, STRIP_HALF_WIDTH_PX + 1, dtype=float)[lines]
    (k, c), resid = np.polyfit(t, best, 1, full=True)[:2]
    # Texture makes single lines' shifts noisy: tilt only when the tilt is clear
    # (|k| over twice its standard error), else trust the smoothed gradient.
    k_err = np.sqrt((resid[0] if resid.size else 0.0) / (t.size - 2) / np.sum((t - t.mean()) ** 2))
    if abs(k) <= 2.0 * k_err:
        return normal
    tangent = np.array([-normal[1], normal[0]])
    refined = normal - k * tangent
    return refined / np.linalg.norm(refined)


def _profile_fit(images: _Images, point, normal, half_span_px: float):
    """(fit, s, log profile) of the profile through point along normal, or the reason it has none.

    A profile that meets masked or clipped pixels is shortened (down to
    MIN_HALF_SPAN_PX) before it is given up: the edge may run close to the object.
    """
    half = half_span_px
    while True:
        if half < MIN_HALF_SPAN_PX:
            return "too close to the image border or to masked/clipped pixels"
        samples = sample_profiles(images.gray, images.valid, point[None], normal[None], half, step_px=STEP_PX,
                                  half_width_px=STRIP_HALF_WIDTH_PX)
        if samples.usable[0]:
            break
        half *= 0.7
    s = samples.offsets_px
    y = np.log(np.maximum(samples.values[0], 1e-300))
    fit = fit_edge_profile(s, y, max_width_px=1.2 * half)
    if fit is None:
        return "no darker side"
    return fit, s, y


def _plateaus(s: np.ndarray, fit: RampFit, extra_px: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """Boolean sample masks of the flat parts beyond the ramp (dark, lit), 1 px + extra_px clear of it."""
    margin = 0.5 * fit.w + 1.0 + extra_px
    return s < fit.s0 - margin, s > fit.s0 + margin


def _shadow_edge_test(images: _Images, centre, normal, half_span_px: float, fit: RampFit, s: np.ndarray,
                      y: np.ndarray) -> tuple[str | None, float]:
    """(why this fitted profile is not a shadow edge on one surface or None, its blue shift (NaN: no colour))."""
    nan = float("nan")
    if fit.rho > RHO_MAX:
        return f"step too shallow (rho {fit.rho:.2f} > {RHO_MAX})", nan
    step = -np.log(fit.rho)
    dark, lit = _plateaus(s, fit)
    need = max(MIN_PLATEAU_PX, PLATEAU_PER_WIDTH * fit.w) / STEP_PX
    if dark.sum() < need or lit.sum() < need:
        return "ramp not inside the profile (too little plateau on one side)", nan
    if fit.residual_rms > MAX_RESIDUAL_PER_STEP * step:
        return (f"poor fit (residual {fit.residual_rms:.3f} > {MAX_RESIDUAL_PER_STEP} x step): texture or another "
                "edge", nan)
    if abs(fit.b) * (s[-1] - s[0]) > MAX_SLOPE_STEP_FRACTION * step:
        return "shading slope comparable to the step: not a clean edge", nan
    ratio = _texture_ratio(images, centre, normal, half_span_px, fit, s)
    if ratio is not None and not TEXTURE_RATIO_LOW <= ratio <= TEXTURE_RATIO_HIGH / np.sqrt(fit.rho):
        return f"texture differs across the edge (dark/lit {ratio:.2f}): two surfaces, not a shadow", nan
    if images.rgb is None:
        return None, nan
    colour = _colour_step_logs(images, centre, normal, half_span_px, fit, s)
    blue = float(colour[2] - colour[0])
    if np.max(np.abs(colour)) > COLOUR_TOL_LOG:
        return f"colour changes across the edge (channel log ratios differ by {np.max(np.abs(colour)):.2f})", blue
    return None, blue


def _texture_ratio(images: _Images, centre, normal, half_span_px, fit, s) -> float | None:
    """Robust std of fine log texture on the dark plateau over that on the lit plateau (None: both smooth).

    Taken over the 2-D strip (every line, not the strip means) and clear of the
    ramp by the high-pass kernel's reach, so the edge itself does not count.
    """
    strips = sample_strips(images.texture, centre[None], normal[None], half_span_px, STEP_PX,
                           STRIP_HALF_WIDTH_PX)[0]                                # (S, T)
    dark, lit = _plateaus(s, fit, extra_px=2.0 * TEXTURE_SIGMA_PX)
    if dark.sum() < 2 or lit.sum() < 2:
        return None
    tex_dark = _robust_std(strips[dark].ravel())
    tex_lit = _robust_std(strips[lit].ravel())
    if max(tex_dark, tex_lit) < SMOOTH_TEXTURE_LOG:
        return None
    return max(tex_dark, SMOOTH_TEXTURE_LOG) / max(tex_lit, SMOOTH_TEXTURE_LOG)


def _colour_step_logs(images: _Images, centre, normal, half_span_px, fit, s) -> np.ndarray:
    """(3,) per-channel log(dark plateau / lit plateau) minus the same for the channel sum."""
    samples = sample_profiles(images.rgb, images.valid, centre[None], normal[None], half_span_px, step_px=STEP_PX,
                              half_width_px=STRIP_HALF_WIDTH_PX)
    vals = np.maximum(samples.values[0], 1e-300)          # (S, 3)
    dark, lit = _plateaus(s, fit)
    steps = np.log(np.median(vals[dark], axis=0)) - np.log(np.median(vals[lit], axis=0))
    sum_step = np.log(np.median(vals[dark].sum(axis=1))) - np.log(np.median(vals[lit].sum(axis=1)))
    return steps - sum_step


def _robust_std(x: np.ndarray) -> float:
    return float(stats.median_abs_deviation(x, scale="normal")) if x.size else 0.0


def _prefer_bluer_umbrae(profiles: list[EdgeProfile]) -> list[EdgeProfile]:
    """Drop the shadow-like profiles whose dark side is not bluer, when enough others' are (blue sky)."""
    idx = [i for i, p in enumerate(profiles) if p.kept]
    bluer = bluer_umbrae(np.array([profiles[i].blue_shift_log for i in idx]))
    if bluer is None:
        return profiles
    out = list(profiles)
    for j, i in enumerate(idx):
        if not bluer[j]:
            out[i] = _with_reason(profiles[i], "dark side not bluer than the lit side while other edges' are: "
                                               "paint, a kerb or a material border, not a skylit umbra")
    return out


def _keep_dominant_mode(profiles: list[EdgeProfile]) -> list[EdgeProfile]:
    """Keep only profiles whose log rho lies near the dominant mode of the shadow-like ones.

    All shadow edges on one surface orientation share rho (one sun, one sky);
    what survives the per-profile tests but sits far from the mode is an albedo
    edge of a similar look or a differently oriented surface.
    """
    idx = [i for i, p in enumerate(profiles) if p.kept]
    if not idx:
        return profiles
    log_rho = np.log([profiles[i].rho for i in idx])
    mode = mode_of_log_rho(log_rho, np.log(RHO_MIN))
    near = np.abs(log_rho - mode) <= MODE_WINDOW_LOG
    # Trim what is far from the median of the mode's members in units of their robust spread.
    centre = np.median(log_rho[near])
    spread = max(_robust_std(log_rho[near]), 0.02)
    inlier = near & (np.abs(log_rho - centre) <= 3.0 * spread)
    out = list(profiles)
    for j, i in enumerate(idx):
        if not inlier[j]:
            out[i] = _with_reason(profiles[i], f"rho {profiles[i].rho:.3f} far from the dominant mode "
                                               f"{np.exp(centre):.3f}")
    return out


def _with_reason(p: EdgeProfile, reason: str) -> EdgeProfile:
    """The profile, no longer kept, for this reason."""
    return dataclasses.replace(p, kept=False, reject_reason=reason)


def _to_full_scale(p: EdgeProfile, work) -> EdgeProfile:
    """A profile measured on the working image, in full-resolution pixels (positions, widths, offsets)."""
    if work.factor == 1:
        return p
    f = float(work.factor)
    return dataclasses.replace(p, position_uv=work.to_full_uv(p.position_uv), width_px=p.width_px * f,
                               offsets_px=p.offsets_px * f)


def _block_bootstrap_median_stderr(rho: np.ndarray, positions_uv: np.ndarray, rng: np.random.Generator) -> float:
    """Std of the median of rho under resampling of spatial blocks of profiles.

    Neighbouring profiles share pixels (strips overlap) and texture, so they are
    not independent: resample square blocks twice the strip width instead.
    """
    block = 2.0 * (2 * STRIP_HALF_WIDTH_PX + 1)
    keys = np.floor(positions_uv / block).astype(np.int64)
    _, labels = np.unique(keys[:, 0] * 1_000_003 + keys[:, 1], return_inverse=True)
    members = [np.nonzero(labels == b)[0] for b in range(labels.max() + 1)]
    n_blocks = len(members)
    if n_blocks < 2:
        return float("nan")
    medians = np.empty(BOOTSTRAP_RESAMPLES)
    for r in range(BOOTSTRAP_RESAMPLES):
        pick = rng.integers(0, n_blocks, n_blocks)
        medians[r] = np.median(rho[np.concatenate([members[b] for b in pick])])
    return float(np.std(medians, ddof=1))


def _rejected(point, normal, reason: str) -> EdgeProfile:
    empty = np.zeros(0)
    return EdgeProfile(np.asarray(point, float), np.asarray(normal, float), float("nan"), float("nan"),
                       float("nan"), False, reason, empty, empty, empty)


def _nothing(reason: str, profiles: list[EdgeProfile]) -> EdgeMeasurement:
    nan = float("nan")
    return EdgeMeasurement(rho=nan, rho_stderr=nan, penumbra_px=nan, penumbra_px_iqr=nan, penumbra_m=None,
                           n_profiles=0, edges_found=False, profiles=profiles, reason=reason)


def _checked_gray(linear_gray) -> np.ndarray:
    arr = np.asarray(linear_gray)
    if arr.ndim != 2:
        raise ValueError(f"linear_gray must be a 2-D (H, W) array, got shape {arr.shape}")
    if min(arr.shape) < 16:
        raise ValueError(f"linear_gray is too small to hold a shadow edge: shape {arr.shape}")
    if not np.issubdtype(arr.dtype, np.number) or np.issubdtype(arr.dtype, np.complexfloating):
        raise ValueError(f"linear_gray must hold real numbers, got dtype {arr.dtype}")
    arr = arr.astype(np.float64)
    if not np.isfinite(arr).any():
        raise ValueError("linear_gray has no finite pixel")
    return arr


def _checked_mask(mask, shape) -> np.ndarray | None:
    if mask is None:
        return None
    m = np.asarray(mask)
    if m.shape != shape:
        raise ValueError(f"mask shape {m.shape} does not match the image shape {shape}")
    return m.astype(bool)


def _checked_rgb(rgb, shape) -> np.ndarray | None:
    if rgb is None:
        return None
    arr = np.asarray(rgb, dtype=np.float64)
    if arr.shape != (*shape, 3):
        raise ValueError(f"linear_rgb must have shape {(*shape, 3)}, got {arr.shape}")
    return arr
