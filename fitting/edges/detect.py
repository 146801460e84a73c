"""Candidate shadow edges in a single photo and profiles sampled across them (NumPy/OpenCV/scikit-image).

Shadows are multiplicative: I = albedo * E, so log I = log albedo + log E and a
shadow edge is a step of log rho in the log image whatever the albedo texture.
All detection therefore works on the log image. This module only finds places
worth measuring and samples them; deciding which are shadow edges is the job of
``fitting.edges.measure``.

Pixel coordinates follow docs/formats.md: (u, v) = (column, row), (0, 0) is the
centre of the top-left pixel.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import cv2
from scipy import ndimage
from skimage import feature, measure

__all__ = ["EdgeCandidates", "LogImage", "ProfileSamples", "WorkImage", "log_image", "detect_edge_candidates",
           "sample_profiles", "sample_strips", "high_pass_log", "max_half_span_inside", "to_work_scale"]

# Gaussian scales (px) of the two Canny passes. Detection only has to find
# edges (each profile fit then locates the ramp to a fraction of a pixel), so
# the scales are large enough that rough albedo texture (concrete, asphalt)
# averages out: at sigma 1.5 px a concrete texture of 0.15 log units gave 15
# times more Canny pixels than the shadow outline, at 4 px none. The larger
# scale still sees wide penumbrae (a ramp of width w has a log-gradient of
# only log(1/rho) / w).
DETECTION_SIGMAS_PX = (4.0, 8.0)
# Connected Canny chains shorter than this (px) are texture specks, not edges.
MIN_CHAIN_PX = 20
# Canny hysteresis thresholds on the gradient of the smoothed log image, in
# log units per pixel: a shadow of rho <= 0.85 (log step >= 0.16) spread over a
# few pixels clears the high one.
CANNY_HIGH_LOG_PER_PX = 0.04
CANNY_LOW_LOG_PER_PX = 0.015
# Half the base (px) over which the bend of an edge is measured: a bit more
# than a profile strip's half-width, so a bend inside a strip shows.
TURN_BASE_PX = 5.0


@dataclass(frozen=True)
class LogImage:
    """The log of a linear image with the pixels that must not be used.

    log: (H, W) float64, natural log of the linear value (floored, see ``log_image``).
    valid: (H, W) bool, False where masked, non-finite, clipped dark or saturated.
    """

    log: np.ndarray
    valid: np.ndarray


@dataclass(frozen=True)
class WorkImage:
    """A photo reduced by an integer factor for edge measurement.

    gray: (H // f, W // f) linear; rgb: (H // f, W // f, 3) linear or None.
    bad: (H // f, W // f) bool, True where half or more of the block's pixels were bad.
    factor: f, full-resolution pixels per working pixel along each axis.
    A working pixel (u, v) covers full-resolution pixels centred at
    f u + (f - 1) / 2, f v + (f - 1) / 2 (pixel centres as in docs/formats.md).
    """

    gray: np.ndarray
    rgb: np.ndarray | None
    bad: np.ndarray
    factor: int

    def to_full_uv(self, uv: np.ndarray) -> np.ndarray:
        """Working pixel coordinates (..., 2) to full-resolution ones."""
        return np.asarray(uv, float) * self.factor + 0.5 * (self.factor - 1)


def to_work_scale(gray: np.ndarray, rgb: np.ndarray | None, bad: np.ndarray, max_side_px: int) -> WorkImage:
    """Box-average a photo by the smallest integer factor that brings its longer side to max_side_px or less.

    Averaging is done in linear units over the good pixels of each block only
    (a clipped pebble does not darken its block), so plateau ratios, and hence
    rho, are unchanged; a ramp of w px becomes one of w / f working pixels.
    Rows and columns beyond a multiple of f are dropped. The working images
    are float64 whatever the input's float type.
    """
    f = max(1, int(np.ceil(max(gray.shape) / float(max_side_px))))
    if f == 1:
        return WorkImage(gray.astype(np.float64), None if rgb is None else rgb.astype(np.float64), bad, 1)
    h, w = gray.shape[0] // f * f, gray.shape[1] // f * f
    size = (w // f, h // f)
    good = ~bad[:h, :w]
    # cv2's INTER_AREA at an integer factor is the exact block mean (and fast on
    # a 4000x3000 photo); the mean over good pixels is mean(x good) / mean(good).
    frac_good = cv2.resize(good.astype(np.float32), size, interpolation=cv2.INTER_AREA).astype(np.float64)

    any_bad = not good.all()

    def mean(x):
        zeroed = np.array(x[:h, :w], dtype=np.float32)      # a copy: the caller's photo is not touched
        if any_bad:
            zeroed[~good] = 0.0
        m = cv2.resize(zeroed, size, interpolation=cv2.INTER_AREA).astype(np.float64)
        scale = np.maximum(frac_good, 1e-12)
        return m / (scale[..., None] if m.ndim == 3 else scale)

    return WorkImage(mean(gray), None if rgb is None else mean(rgb), frac_good * 2 <= 1.0 + 1e-6, f)


@dataclass(frozen=True)
class EdgeCandidates:
    """Points on candidate edges of the log image.

    points_uv: (N, 2) float, pixel coordinates (u, v) of edge pixels.
    normals_uv: (N, 2) float, unit vectors across the edge towards the brighter side.
    sigma_px: (N,) float, Gaussian scale (px) of the Canny pass that found the point.
    turn_deg: (N,) float, angle (degrees) between the edge normals TURN_BASE_PX
        before and after the point along the edge: large at corners and tight curves.
    """

    points_uv: np.ndarray
    normals_uv: np.ndarray
    sigma_px: np.ndarray
    turn_deg: np.ndarray

    def __len__(self) -> int:
        return int(self.points_uv.shape[0])


@dataclass(frozen=True)
class ProfileSamples:
    """Profiles across edges, averaged over a short strip along the edge.

    offsets_px: (S,) float, signed distance along the normal (towards the lit
        side), shared by all profiles (the longest profile's).
    values: (N, S) float, mean linear value over the strip; (N, S, C) for a
        (H, W, C) image. 0 where a profile has no good line, or no sample.
    usable: (N,) bool, False where, at some position along the profile, half or
        more of the strip's lines fell outside the image or on invalid pixels
        (values average the good lines only).
    present: (N, S) bool, the samples within each profile's own half-span.
    """

    offsets_px: np.ndarray
    values: np.ndarray
    usable: np.ndarray
    present: np.ndarray


def log_image(linear: np.ndarray, ignore: np.ndarray | None = None) -> LogImage:
    """Log of a linear gray image (H, W), with invalid pixels flagged.

    ignore: (H, W) bool, True = do not use (masked or clipped pixels).
    Dark pixels are floored at 1e-4 of the 99.9th percentile so that log stays
    finite; pixels at or below that floor (crushed blacks, where ratios are
    meaningless) are invalid, as are non-finite and ``ignore`` pixels.
    """
    finite = np.isfinite(linear)
    valid = finite.copy()
    if ignore is not None:
        valid &= ~ignore
    if not valid.any():
        return LogImage(np.zeros(linear.shape), valid)
    top = float(np.percentile(linear[valid], 99.9))
    floor = max(top * 1e-4, 1e-30)
    values = np.where(finite, linear, floor)
    valid &= values > floor
    return LogImage(np.log(np.maximum(values, floor)), valid)


def detect_edge_candidates(img: LogImage, max_points: int, rng: np.random.Generator,
                           sigmas_px: tuple[float, ...] = DETECTION_SIGMAS_PX,
                           min_chain_px: float = MIN_CHAIN_PX) -> EdgeCandidates:
    """Points on long Canny edges of the log image, spread evenly over the edges.

    Canny runs at each scale in ``sigmas_px``; chains shorter than ``min_chain_px``
    are dropped. At most ``max_points`` points are returned, one per cell of a
    square grid sized so that the edges fill about that many cells (so long edges
    get many points and every part of them gets some); the point within a cell
    is chosen by ``rng``.
    """
    log = img.log
    # Fill invalid pixels with a smooth local value so their borders do not
    # become edges (the mask is also given to Canny, which ignores them).
    filled = _fill_invalid(log, img.valid)
    # Canny must not fire at the boundary of ignored regions: erode the valid area.
    usable = ndimage.binary_erosion(img.valid, iterations=2, border_value=0)
    pts, nrm, sig, turn = [], [], [], []
    for sigma in sigmas_px:
        # skimage's canny thresholds the magnitude of scipy's Sobel of the smoothed
        # image, 8 times the per-pixel derivative: thresholds below are scaled to
        # match, so they read in log units per pixel. Normals come from the same
        # smoothed gradient.
        smooth = ndimage.gaussian_filter(filled, sigma)
        gy = ndimage.sobel(smooth, axis=0) / 8.0
        gx = ndimage.sobel(smooth, axis=1) / 8.0
        edges = feature.canny(filled, sigma=sigma, low_threshold=CANNY_LOW_LOG_PER_PX * 8.0,
                              high_threshold=CANNY_HIGH_LOG_PER_PX * 8.0, mask=usable,
                              mode="nearest")
        labels = measure.label(edges, connectivity=2)
        if labels.max() == 0:
            continue
        sizes = np.bincount(labels.ravel())
        long_chain = sizes >= min_chain_px
        long_chain[0] = False
        rows, cols = np.nonzero(long_chain[labels])
        g = np.stack([gx[rows, cols], gy[rows, cols]], axis=1)
        gnorm = np.linalg.norm(g, axis=1)
        ok = gnorm > 0
        p = np.stack([cols[ok], rows[ok]], axis=1).astype(float)
        n = g[ok] / gnorm[ok, None]
        pts.append(p)
        nrm.append(n)
        sig.append(np.full(int(ok.sum()), float(sigma)))
        turn.append(_turn_deg(gx, gy, p, n))
    if not pts:
        return EdgeCandidates(np.zeros((0, 2)), np.zeros((0, 2)), np.zeros(0), np.zeros(0))
    points = np.concatenate(pts)
    keep = _spread_evenly(points, max_points, rng)
    return EdgeCandidates(points[keep], np.concatenate(nrm)[keep], np.concatenate(sig)[keep],
                          np.concatenate(turn)[keep])


def sample_profiles(linear: np.ndarray, valid: np.ndarray, points_uv: np.ndarray, normals_uv: np.ndarray,
                    half_span_px, step_px: float = 0.5, half_width_px: int = 3) -> ProfileSamples:
    """Sample profiles across edges with bilinear interpolation (scipy map_coordinates).

    linear: (H, W) or (H, W, C) linear image; valid: (H, W) bool.
    points_uv, normals_uv: (N, 2) profile centres and unit normals (pixel units).
    half_span_px: a float, or (N,) per profile. Each profile runs along its
    normal from -half_span_px to +half_span_px in steps of step_px (all on one
    grid of offsets, padded to the longest); every sample is the mean over the
    good ones of 2 * half_width_px + 1 parallel lines 1 px apart (along the
    edge), which averages albedo texture and noise down.
    """
    offsets, coords, shape, present = _strip_coords(points_uv, normals_uv, half_span_px, step_px, half_width_px)
    h, w = valid.shape
    inside = (coords[0] >= 0) & (coords[0] <= h - 1) & (coords[1] >= 0) & (coords[1] <= w - 1)
    # A sample is good only if all four pixels it interpolates from are valid.
    rc = np.floor(np.clip(coords, 0, [[h - 1], [w - 1]])).astype(int)
    r1 = np.minimum(rc[0] + 1, h - 1)
    c1 = np.minimum(rc[1] + 1, w - 1)
    good = (inside & valid[rc[0], rc[1]] & valid[r1, rc[1]] & valid[rc[0], c1] & valid[r1, c1]).reshape(shape)
    good &= present[:, :, None]
    # Scattered bad pixels (a clipped pebble, a hot pixel) only thin the strip;
    # a profile is unusable where half its lines are bad at some position (it
    # runs into a masked object or off the image).
    n_good = good.sum(axis=2)
    usable = ((n_good * 2 > shape[2]) | ~present).all(axis=1)
    weights = good / np.maximum(n_good, 1)[..., None]

    def strip_means(channel):
        raw = ndimage.map_coordinates(channel, coords, order=1, mode="nearest").reshape(shape)
        # where() rather than a product: bad samples may be NaN or inf, and NaN * 0 is NaN.
        return (np.where(good, raw, 0.0) * weights).sum(axis=2)

    if linear.ndim == 2:
        values = strip_means(linear)
    else:
        values = np.stack([strip_means(linear[..., c]) for c in range(linear.shape[2])], axis=-1)
    return ProfileSamples(offsets, values, usable, present)


def sample_strips(image: np.ndarray, points_uv: np.ndarray, normals_uv: np.ndarray, half_span_px,
                  step_px: float = 0.5, half_width_px: int = 3) -> np.ndarray:
    """The un-averaged strip grid of ``sample_profiles``: (N, S, 2 * half_width_px + 1) values of a (H, W) image.

    With per-profile half-spans, samples beyond a profile's own span (see
    ``ProfileSamples.present``) hold whatever lies there.
    """
    _, coords, shape, _ = _strip_coords(points_uv, normals_uv, half_span_px, step_px, half_width_px)
    return ndimage.map_coordinates(image, coords, order=1, mode="nearest").reshape(shape)


def high_pass_log(img: LogImage, sigma_px: float = 1.0) -> np.ndarray:
    """Fine albedo texture (plus noise): log minus its Gaussian blur, (H, W) in log units.

    Shading cannot change it (log I = log albedo + log E and E is smooth away
    from edges), so it is the same on both sides of a shadow edge on one
    surface, and usually not across the border of two materials.
    """
    filled = _fill_invalid(img.log, img.valid)
    return filled - ndimage.gaussian_filter(filled, sigma_px)


def max_half_span_inside(point_uv: np.ndarray, normal_uv: np.ndarray, shape: tuple[int, int],
                         half_width_px: int = 3):
    """Largest half-span (px) whose strip, centred at point_uv along normal_uv, stays inside the image.

    point_uv, normal_uv: (2,) (returns a float) or (N, 2) (returns (N,)).
    """
    pts = np.asarray(point_uv, float)
    single = pts.ndim == 1
    pts = pts.reshape(-1, 2)
    nrm = np.asarray(normal_uv, float).reshape(-1, 2)
    h, w = shape
    tangent = np.stack([-nrm[:, 1], nrm[:, 0]], axis=1)
    best = np.full(pts.shape[0], np.inf)
    for corner in (pts + half_width_px * tangent, pts - half_width_px * tangent):
        for axis, size in ((0, w), (1, h)):
            d = nrm[:, axis]
            c = corner[:, axis]
            flat = np.abs(d) < 1e-12
            # both directions +s and -s must stay inside [0, size - 1]
            with np.errstate(divide="ignore", invalid="ignore"):
                room = np.where(d > 0, np.minimum((size - 1 - c) / d, c / d),
                                np.minimum(c / -d, (size - 1 - c) / -d))
            room = np.where(flat, np.where((c >= 0) & (c <= size - 1), np.inf, 0.0), room)
            best = np.minimum(best, room)
    best = np.maximum(best, 0.0)
    return float(best[0]) if single else best


def _strip_coords(points_uv, normals_uv, half_span_px, step_px, half_width_px):
    """Offsets (S,), map_coordinates (row, col) coordinates (2, N*S*T), the (N, S, T) shape, present (N, S)."""
    points_uv = np.asarray(points_uv, float).reshape(-1, 2)
    normals_uv = np.asarray(normals_uv, float).reshape(-1, 2)
    n = points_uv.shape[0]
    n_halves = np.floor(np.broadcast_to(np.asarray(half_span_px, float), (n,)) / step_px + 1e-9).astype(int)
    n_half = int(n_halves.max()) if n else 0
    k = np.arange(-n_half, n_half + 1)
    offsets = k * step_px
    present = np.abs(k)[None, :] <= n_halves[:, None]
    tangents = np.stack([-normals_uv[:, 1], normals_uv[:, 0]], axis=1)
    t_off = np.arange(-half_width_px, half_width_px + 1, dtype=float)
    s = offsets[None, :, None]
    t = t_off[None, None, :]
    u = points_uv[:, None, None, 0] + s * normals_uv[:, None, None, 0] + t * tangents[:, None, None, 0]
    v = points_uv[:, None, None, 1] + s * normals_uv[:, None, None, 1] + t * tangents[:, None, None, 1]
    return offsets, np.stack([v.ravel(), u.ravel()]), (n, offsets.size, t_off.size), present


def _turn_deg(gx: np.ndarray, gy: np.ndarray, points_uv: np.ndarray, normals_uv: np.ndarray) -> np.ndarray:
    """Angle (deg) between the gradient directions TURN_BASE_PX to either side of each point along its edge."""
    tangents = np.stack([-normals_uv[:, 1], normals_uv[:, 0]], axis=1)
    ends = []
    for sign in (-1.0, 1.0):
        q = points_uv + sign * TURN_BASE_PX * tangents
        coords = [q[:, 1], q[:, 0]]
        g = np.stack([ndimage.map_coordinates(gx, coords, order=1, mode="nearest"),
                      ndimage.map_coordinates(gy, coords, order=1, mode="nearest")], axis=1)
        ends.append(g / np.maximum(np.linalg.norm(g, axis=1, keepdims=True), 1e-300))
    cos = np.clip(np.sum(ends[0] * ends[1], axis=1), -1.0, 1.0)
    return np.degrees(np.arccos(cos))


def _fill_invalid(log: np.ndarray, valid: np.ndarray) -> np.ndarray:
    """Replace invalid pixels by their nearest valid neighbour's value."""
    if valid.all():
        return log
    idx = ndimage.distance_transform_edt(~valid, return_distances=False, return_indices=True)
    return log[tuple(idx)]


def _spread_evenly(points: np.ndarray, max_points: int, rng: np.random.Generator) -> np.ndarray:
    """Indices of at most max_points points, at most one per grid cell, cells sized to give about max_points."""
    n = points.shape[0]
    if n <= max_points:
        return np.arange(n)
    order = rng.permutation(n)
    cell = 1.0
    chosen = order
    for _ in range(40):
        keys = np.floor(points[order] / cell).astype(np.int64)
        _, first = np.unique(keys[:, 0] * 1_000_003 + keys[:, 1], return_index=True)
        chosen = order[np.sort(first)]
        if chosen.size <= max_points:
            break
        cell *= 1.25
    if chosen.size > max_points:
        chosen = rng.choice(chosen, size=max_points, replace=False)
    return chosen
