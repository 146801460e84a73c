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
import warnings as _warnings
from dataclasses import dataclass

import numpy as np

from fitting.edges.detect import (MIN_CHAIN_PX, LogImage, detect_edge_candidates, high_pass_log, log_image, max_half_span_inside,
                                 sample_profiles, sample_strips, to_work_scale)
from fitting.edges.ramp import (RHO_MIN, SAMPLING_BLUR_PX, RampFit, RampFits, fit_edge_profile, fit_edge_profiles,
                               ramp_alpha, ramp_log_model, robust_std)
from fitting.edges.ground_region import ground_region
from fitting.edges.cues import (DARK_SIDE_STEP_PX, MODE_WINDOW_LOG, bluer_umbrae, dark_side_regions,
                                  edge_evidence, edge_structures, mode_of_log_rho, textured_outlines)
from fitting.verdict.edge_rules import judge_edges, nothing_measured
from fitting.verdict.evidence import EdgeEvidence
from fitting.verdict.outcome import Verdict

__all__ = ["EdgeMeasurement", "EdgeProfile", "RampFit", "measure_shadow_edges", "fit_edge_profile", "ramp_alpha",
           "ramp_log_model"]

NO_EDGE_REASON = "no shadow edge found"

STEP_PX = 0.5              # sample spacing along a profile
STRIP_HALF_WIDTH_PX = 3    # each sample averages 7 lines 1 px apart along the edge
RHO_MAX = 0.9              # a step shallower than this is not treated as a shadow
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
# Candidates are fitted in chunks of this many, sorted by profile length: each
# chunk is one batched sampling and one batched fit per pass, padded only to
# the longest profile of the chunk.
CHUNK_PROFILES = 256


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
    texture_ratio: robust std of the fine log texture on the dark plateau over
        that on the lit plateau (about 1 on one surface); NaN when not measured.
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
    texture_ratio: float = float("nan")


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
    verdict: the rule book's (``fitting.verdict.edge_rules``) on ``evidence``, the
        cues of the kept profiles (``fitting.edges.cues.edge_evidence``; None when
        nothing was measured). Its ``warnings`` (also ``warnings`` here) are
        one-line reasons to doubt the result: edges that disagree, too few
        profiles, profiles scattered over unrelated structures, dark sides
        scattered over separate dark regions; ``reliable`` is False when there
        is any warning (the value is still given).
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
    verdict: Verdict = dataclasses.field(default_factory=nothing_measured)
    evidence: EdgeEvidence | None = None

    @property
    def warnings(self) -> tuple[str, ...]:
        return self.verdict.warnings

    @property
    def reliable(self) -> bool:
        return self.verdict.reliable


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
    # One pass over the channels (a 4000x3000 photo is 36 M values): NaN and
    # inf propagate into the channel max or min, so a finite pair means three
    # finite channels. (Element-wise over channel views: a reduction over the
    # last axis of (H, W, 3) is about 8 times slower.)
    top = None if rgb is None else np.maximum(np.maximum(rgb[..., 0], rgb[..., 1]), rgb[..., 2])
    if rgb is not None:
        bad |= ~(np.isfinite(top) & np.isfinite(np.minimum(np.minimum(rgb[..., 0], rgb[..., 1]), rgb[..., 2])))
    if saturation_level is not None:
        bad |= gray >= saturation_level
        if rgb is not None:
            bad |= top >= saturation_level
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
    profiles = _drop_textured_outlines(profiles, work.gray.shape)
    shadow_like_log_rho = np.log([p.rho for p in profiles if p.kept])
    profiles = _keep_dominant_mode(profiles)
    dark_sides = _dark_side_labels(img, profiles)
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
    evidence = edge_evidence(shadow_like_log_rho, positions, gray.shape, np.log(RHO_MIN), log_rho, dark_sides)
    return EdgeMeasurement(rho=rho, rho_stderr=rho_stderr, penumbra_px=float(q50), penumbra_px_iqr=float(q75 - q25),
                           penumbra_m=None if pixel_m is None else float(q50 * pixel_m), n_profiles=len(kept),
                           edges_found=True, profiles=profiles, reason=None, verdict=judge_edges(evidence),
                           evidence=evidence)


@dataclass(frozen=True)
class _Images:
    """The arrays every profile is sampled from."""

    gray: np.ndarray            # (H, W) linear
    valid: np.ndarray           # (H, W) bool
    texture: np.ndarray         # (H, W) high-pass log (fine texture plus noise)
    rgb: np.ndarray | None      # (H, W, 3) linear, or None


def _fit_candidates(images: _Images, candidates) -> list[EdgeProfile | None]:
    """Sample, fit and screen every candidate (two passes: the second spans the fitted ramp).

    Candidates go through in chunks of similar profile length, each chunk as
    arrays (one batched sampling and one batched fit per pass), and come out
    in their original order.
    """
    shape = images.gray.shape
    max_half = max(MIN_HALF_SPAN_PX, 0.25 * min(shape))
    points, normals = candidates.points_uv, candidates.normals_uv
    profiles: list[EdgeProfile | None] = [None] * len(candidates)
    for i in np.nonzero(candidates.turn_deg > MAX_TURN_DEG)[0]:
        profiles[i] = _rejected(points[i], normals[i],
                                f"edge bends {candidates.turn_deg[i]:.0f} deg within 10 px (a corner)")
    room = max_half_span_inside(points, normals, shape, STRIP_HALF_WIDTH_PX)
    half1 = np.minimum(np.minimum(3.0 * candidates.sigma_px + 6.0, max_half), room)
    todo = np.nonzero(candidates.turn_deg <= MAX_TURN_DEG)[0]
    todo = todo[np.argsort(half1[todo], kind="stable")]
    for start in range(0, todo.size, CHUNK_PROFILES):
        idx = todo[start:start + CHUNK_PROFILES]
        for i, p in zip(idx, _fit_chunk(images, points[idx], normals[idx], half1[idx], max_half)):
            profiles[i] = p
    return profiles


def _fit_chunk(images: _Images, points, normals, half1, max_half) -> list[EdgeProfile | None]:
    """Both passes and the shadow-edge tests for (N, 2) points and normals with first-pass half-spans (N,)."""
    first = _sampled_fits(images, points, normals, half1)
    out: list[EdgeProfile | None] = [None] * len(points)
    for i in np.nonzero(first.reasons != None)[0]:    # noqa: E711 (element-wise)
        out[i] = _rejected(points[i], normals[i], first.reasons[i])
    ok = np.nonzero(first.reasons == None)[0]          # noqa: E711
    if ok.size:
        # Straighten the normal (the smoothed gradient leans near corners and in
        # texture), re-centre on the fitted ramp and span enough plateau beyond it.
        refined = _refined_normals(images, points[ok], normals[ok], first.half[ok], first.params(ok))
        centres = points[ok] + first.fits.s0[ok, None] * refined
        room = max_half_span_inside(centres, refined, images.gray.shape, STRIP_HALF_WIDTH_PX)
        half2 = np.minimum(np.minimum(first.fits.w[ok] * (0.5 + PLATEAU_PER_WIDTH) + PLATEAU_EXTRA_PX, max_half), room)
        second = _sampled_fits(images, centres, refined, half2)
        passed = second.reasons == None                # noqa: E711
        reasons, blue, texture = _shadow_edge_tests(images, centres, refined, second, passed)
        f = second.fits
        for j, i in enumerate(ok):
            if not passed[j]:
                out[i] = _rejected(centres[j], refined[j], second.reasons[j])
                continue
            m = second.present[j]
            out[i] = EdgeProfile(position_uv=centres[j] + f.s0[j] * refined[j], normal_uv=refined[j],
                                 rho=float(f.rho[j]), width_px=float(f.w[j]), residual=float(f.residual_rms[j]),
                                 kept=reasons[j] is None, reject_reason=reasons[j],
                                 offsets_px=second.s[m] - f.s0[j], observed_log=second.y[j, m],
                                 fitted_log=f.fitted[j, m], blue_shift_log=float(blue[j]),
                                 texture_ratio=float(texture[j]))
    return out


@dataclass(frozen=True)
class _Pass:
    """One pass of sampled and fitted profiles (N of them, on one grid of S offsets).

    s: (S,) offsets; y: (N, S) log strip means; present: (N, S) the samples of
    each profile; half: (N,) each profile's half-span actually sampled (px);
    fits: the batched ramp fits; reasons: (N,) object array, why a profile has
    no fit (None: it has one).
    """

    s: np.ndarray
    y: np.ndarray
    present: np.ndarray
    half: np.ndarray
    fits: RampFits
    reasons: np.ndarray

    def params(self, idx) -> np.ndarray:
        """(len(idx), 5) fitted (a, b, s0, w, rho)."""
        f = self.fits
        return np.stack([f.a[idx], f.b[idx], f.s0[idx], f.w[idx], f.rho[idx]], axis=1)


def _sampled_fits(images: _Images, points, normals, halves) -> _Pass:
    """Sample the profiles through points along normals (half-spans (N,)) and fit them all at once.

    A profile that meets masked or clipped pixels is shortened (by 0.7, down to
    MIN_HALF_SPAN_PX) before it is given up: the edge may run close to the object.
    """
    n = len(points)
    half = np.asarray(halves, float).copy()
    s = _offsets(half.max() if n else 0.0)
    values = np.ones((n, s.size))
    present = np.zeros((n, s.size), bool)
    reasons = np.full(n, None, dtype=object)
    todo = np.arange(n)
    while todo.size:
        short = half[todo] < MIN_HALF_SPAN_PX
        reasons[todo[short]] = "too close to the image border or to masked/clipped pixels"
        todo = todo[~short]
        if not todo.size:
            break
        samples = sample_profiles(images.gray, images.valid, points[todo], normals[todo], half[todo],
                                  step_px=STEP_PX, half_width_px=STRIP_HALF_WIDTH_PX)
        lo = (s.size - samples.offsets_px.size) // 2        # the same grid, centred: a slice of s
        good = todo[samples.usable]
        values[good, lo:lo + samples.offsets_px.size] = samples.values[samples.usable]
        present[good, lo:lo + samples.offsets_px.size] = samples.present[samples.usable]
        todo = todo[~samples.usable]
        half[todo] *= 0.7
    y = np.log(np.maximum(values, 1e-300))
    fits = fit_edge_profiles(s, y, present, 1.2 * half)
    reasons[(reasons == None) & ~fits.ok] = "no darker side"      # noqa: E711
    sampled = (np.abs(s)[None, :] * present).max(axis=1)
    return _Pass(s, y, present, sampled, fits, reasons)


def _offsets(half_span_px: float) -> np.ndarray:
    """(S,) the sample offsets of a profile of this half-span (the grid of ``sample_profiles``)."""
    k = int(np.floor(half_span_px / STEP_PX + 1e-9))
    return np.arange(-k, k + 1) * STEP_PX


def _refined_normals(images: _Images, points, normals, half_span_px, params) -> np.ndarray:
    """(N, 2) edge normals corrected by the tilt of the ramp across each strip's lines.

    params: (N, 5) fitted (a, b, s0, w, rho) of each profile at its half-span (N,).
    Each of the strip's 2 T + 1 lines is matched (least squares over a shift
    and an offset, so line-to-line albedo does not matter) to the fitted
    ramp; a straight line through the shifts against the lines' positions
    gives the edge's slope k relative to the tangent, and the normal becomes
    normalize(n - k t). With fewer than 4 usable lines the normal is kept.
    """
    s = _offsets(float(np.max(half_span_px)))
    present = np.abs(s)[None, :] <= np.asarray(half_span_px, float)[:, None] + 1e-9          # (N, S)
    grid = sample_strips(images.gray, points, normals, half_span_px, STEP_PX, STRIP_HALF_WIDTH_PX)  # (N, S, T)
    good = sample_strips(images.valid.astype(float), points, normals, half_span_px, STEP_PX,
                         STRIP_HALF_WIDTH_PX) > 0.999
    lines = (good | ~present[:, :, None]).all(axis=1)                                       # (N, T)
    # Samples outside a profile's span may lie on masked (NaN) pixels: zero them, never multiply NaN by 0.
    logs = np.where(present[:, :, None], np.log(np.maximum(grid, 1e-300)), 0.0).transpose(0, 2, 1)  # (N, T, S)
    shifts = np.arange(-NORMAL_SHIFT_MAX_PX, NORMAL_SHIFT_MAX_PX + 1e-9, 0.1)
    a, b, s0, w, rho = (params[:, i, None, None] for i in range(5))
    templates = ramp_log_model(s[None, None, :] - shifts[None, :, None], a, b, s0, w, rho, SAMPLING_BLUR_PX)
    # var over s of (line - template), offset free: var(x) + var(t) - 2 cov(x, t), on each profile's samples.
    m = present[:, None, :].astype(float)
    cnt = present.sum(axis=1)[:, None, None]
    xc = (logs - (logs * m).sum(axis=2, keepdims=True) / cnt) * m                           # (N, T, S)
    tc = (templates - (templates * m).sum(axis=2, keepdims=True) / cnt) * m                 # (N, D, S)
    cost = ((xc ** 2).sum(axis=2)[:, :, None] + (tc ** 2).sum(axis=2)[:, None, :]
            - 2.0 * np.einsum("nts,nds->ntd", xc, tc))                                      # (N, T, D)
    best = shifts[np.argmin(cost, axis=2)]                                                  # (N, T)
    t = np.arange(-STRIP_HALF_WIDTH_PX, STRIP_HALF_WIDTH_PX + 1, dtype=float)[None, :]
    wl = lines.astype(float)
    nl = np.maximum(wl.sum(axis=1), 1.0)
    tm = (t * wl).sum(axis=1) / nl
    bm = (best * wl).sum(axis=1) / nl
    stt = (wl * (t - tm[:, None]) ** 2).sum(axis=1)
    with np.errstate(divide="ignore", invalid="ignore"):
        k = (wl * (t - tm[:, None]) * (best - bm[:, None])).sum(axis=1) / stt
        resid = (wl * (best - bm[:, None] - k[:, None] * (t - tm[:, None])) ** 2).sum(axis=1)
        k_err = np.sqrt(resid / (nl - 2.0) / stt)
    # Texture makes single lines' shifts noisy: tilt only when the tilt is clear
    # (|k| over twice its standard error), else trust the smoothed gradient.
    tilt = (lines.sum(axis=1) >= 4) & (np.abs(k) > 2.0 * k_err)
    tangent = np.stack([-normals[:, 1], normals[:, 0]], axis=1)
    refined = normals - np.where(tilt, k, 0.0)[:, None] * tangent
    return refined / np.linalg.norm(refined, axis=1, keepdims=True)


def _plateaus(s: np.ndarray, present: np.ndarray, s0: np.ndarray, w: np.ndarray, extra_px: float = 0.0):
    """(N, S) boolean masks of the flat parts beyond each ramp (dark, lit), 1 px + extra_px clear of it."""
    margin = (0.5 * w + 1.0 + extra_px)[:, None]
    return present & (s[None] < s0[:, None] - margin), present & (s[None] > s0[:, None] + margin)


def _shadow_edge_tests(images: _Images, centres, normals, fitted: _Pass, passed: np.ndarray):
    """(reasons (N,) why each fitted profile is not a shadow edge on one surface or None, blue shifts (N,),
    texture ratios dark/lit (N,)).

    Only the profiles with ``passed`` are tested (the others keep their pass's reason); blue is NaN
    for a profile rejected before the colour test, or without colour.
    """
    f, s, present = fitted.fits, fitted.s, fitted.present
    n = len(centres)
    reasons = np.full(n, None, dtype=object)
    blue = np.full(n, np.nan)
    rho = np.where(passed, f.rho, 0.5)
    w, s0 = np.where(passed, f.w, 1.0), np.where(passed, f.s0, 0.0)
    step = -np.log(rho)
    dark, lit = _plateaus(s, present, s0, w)
    need = np.maximum(MIN_PLATEAU_PX, PLATEAU_PER_WIDTH * w) / STEP_PX
    ratio = _texture_ratios(images, centres, normals, fitted.half, s, present, s0, w)
    colour = None if images.rgb is None else _colour_step_logs(images, centres, normals, fitted.half, s, dark, lit)
    for i in np.nonzero(passed)[0]:
        if rho[i] > RHO_MAX:
            reasons[i] = f"step too shallow (rho {rho[i]:.2f} > {RHO_MAX})"
        elif dark[i].sum() < need[i] or lit[i].sum() < need[i]:
            reasons[i] = "ramp not inside the profile (too little plateau on one side)"
        elif f.residual_rms[i] > MAX_RESIDUAL_PER_STEP * step[i]:
            reasons[i] = (f"poor fit (residual {f.residual_rms[i]:.3f} > {MAX_RESIDUAL_PER_STEP} x step): texture "
                          "or another edge")
        elif abs(f.b[i]) * 2.0 * fitted.half[i] > MAX_SLOPE_STEP_FRACTION * step[i]:
            reasons[i] = "shading slope comparable to the step: not a clean edge"
        elif np.isfinite(ratio[i]) and not TEXTURE_RATIO_LOW <= ratio[i] <= TEXTURE_RATIO_HIGH / np.sqrt(rho[i]):
            reasons[i] = f"texture differs across the edge (dark/lit {ratio[i]:.2f}): two surfaces, not a shadow"
        elif colour is not None:
            blue[i] = colour[i, 2] - colour[i, 0]
            worst = np.max(np.abs(colour[i]))
            if worst > COLOUR_TOL_LOG:
                reasons[i] = f"colour changes across the edge (channel log ratios differ by {worst:.2f})"
    return reasons, blue, ratio


def _texture_ratios(images: _Images, centres, normals, half, s, present, s0, w) -> np.ndarray:
    """(N,) robust std of fine log texture on the dark plateau over that on the lit plateau (NaN: both smooth).

    Taken over the 2-D strip (every line, not the strip means) and clear of the
    ramp by the high-pass kernel's reach, so the edge itself does not count.
    """
    strips = sample_strips(images.texture, centres, normals, half, STEP_PX, STRIP_HALF_WIDTH_PX)   # (N, S, T)
    dark, lit = _plateaus(s, present, s0, w, extra_px=2.0 * TEXTURE_SIGMA_PX)
    n = len(centres)
    tex_dark = robust_std(np.where(dark[:, :, None], strips, np.nan).reshape(n, -1), axis=1)
    tex_lit = robust_std(np.where(lit[:, :, None], strips, np.nan).reshape(n, -1), axis=1)
    ratio = np.maximum(tex_dark, SMOOTH_TEXTURE_LOG) / np.maximum(tex_lit, SMOOTH_TEXTURE_LOG)
    smooth = np.maximum(tex_dark, tex_lit) < SMOOTH_TEXTURE_LOG
    return np.where((dark.sum(axis=1) < 2) | (lit.sum(axis=1) < 2) | smooth, np.nan, ratio)


def _colour_step_logs(images: _Images, centres, normals, half, s, dark, lit) -> np.ndarray:
    """(N, 3) per-channel log(dark plateau / lit plateau) minus the same for the channel sum."""
    samples = sample_profiles(images.rgb, images.valid, centres, normals, half, step_px=STEP_PX,
                              half_width_px=STRIP_HALF_WIDTH_PX)
    vals = np.maximum(samples.values, 1e-300)                                                  # (N, S, 3)
    lo = (s.size - samples.offsets_px.size) // 2
    dark, lit = dark[:, lo:lo + samples.offsets_px.size], lit[:, lo:lo + samples.offsets_px.size]

    def median(x, where):
        with np.errstate(all="ignore"), _warnings.catch_warnings():
            _warnings.simplefilter("ignore", RuntimeWarning)
            return np.nanmedian(np.where(where, x, np.nan), axis=1)

    steps = np.log(median(vals, dark[..., None])) - np.log(median(vals, lit[..., None]))
    total = vals.sum(axis=2)
    sum_step = np.log(median(total, dark)) - np.log(median(total, lit))
    return steps - sum_step[:, None]


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


def _drop_textured_outlines(profiles: list[EdgeProfile], shape: tuple[int, int]) -> list[EdgeProfile]:
    """Drop the shadow-like profiles on outlines whose texture changes across them (``textured_outlines``)."""
    idx = [i for i, p in enumerate(profiles) if p.kept]
    if not idx:
        return profiles
    labels = edge_structures(np.array([profiles[i].position_uv for i in idx]), shape)
    ratios = np.array([profiles[i].texture_ratio for i in idx])
    rho = np.array([profiles[i].rho for i in idx])
    drop = textured_outlines(ratios, rho, labels)
    out = list(profiles)
    for j, i in enumerate(idx):
        if drop[j]:
            median = np.nanmedian((ratios * np.sqrt(rho))[labels == labels[j]])
            out[i] = _with_reason(profiles[i], f"the texture changes across this whole outline (dark/lit x sqrt(rho) "
                                               f"median {median:.2f}): a border between two materials, not a shadow")
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
    spread = max(robust_std(log_rho[near]), 0.02)
    inlier = near & (np.abs(log_rho - centre) <= 3.0 * spread)
    out = list(profiles)
    for j, i in enumerate(idx):
        if not inlier[j]:
            out[i] = _with_reason(profiles[i], f"rho {profiles[i].rho:.3f} far from the dominant mode "
                                               f"{np.exp(centre):.3f}")
    return out


def _dark_side_labels(img, profiles: list[EdgeProfile]) -> np.ndarray | None:
    """``dark_side_regions`` of the kept profiles' dark sides (working-scale positions) on the working
    log image, or None without kept profiles.

    Threshold: halfway in log between the kept profiles' median umbra and lit levels (the fitted model at
    the ends of each profile). The rule book warns on scattered dark sides rather than dropping profiles:
    on the street preset and DSC_0569 the kept profiles' dark sides fall in one or a few large regions,
    and dropping the profiles on small regions would remove true shadow profiles whose umbra is cut up by
    texture or masks, with nothing gained for the value (see docs/edge_measure.md).
    """
    kept = [p for p in profiles if p.kept]
    if not kept:
        return None
    threshold = float(np.median([0.5 * (p.fitted_log[0] + p.fitted_log[-1]) for p in kept]))
    dark_uv = np.array([p.position_uv - p.normal_uv * (0.5 * p.width_px + DARK_SIDE_STEP_PX) for p in kept])
    return dark_side_regions(img.log, img.valid, dark_uv, threshold)


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
    # float32 stays float32 (no full-size copy): the working scale is float64.
    arr = arr if arr.dtype in (np.float32, np.float64) else arr.astype(np.float64)
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
    arr = np.asarray(rgb)
    if arr.dtype not in (np.float32, np.float64):
        arr = arr.astype(np.float64)
    if arr.shape != (*shape, 3):
        raise ValueError(f"linear_rgb must have shape {(*shape, 3)}, got {arr.shape}")
    return arr
