"""What a fit keeps of one photo (``PhotoSamples``), and the choices every receiver's sampling shares:
the white sheet's mask, a stable random pick of pixels, and the error for a shadow out of view."""

from __future__ import annotations

import dataclasses

import cv2
import numpy as np

from softshadow.internal import PointPlan

__all__ = ["NoShadowInView", "PhotoSamples", "paper_mask", "stable_pick"]


def stable_pick(rows: np.ndarray, cols: np.ndarray, shape: tuple[int, int], n: int, seed: int) -> np.ndarray:
    """Indices (sorted, at most ``n``) of the pixels (rows, cols) (m,) to keep: the ``n`` with the
    smallest value of one fixed random image (``shape``, drawn from ``seed``).

    Common random numbers: two candidate sets that overlap keep the same pixels where they
    overlap, so a slightly different band (a level of detail of the mesh, ``fitting.solve.lod``, or a
    nudged sun) changes the fit by what the model changes, not by a new random draw of pixels
    (a fresh ``rng.choice`` moved k of the 41k dragon by 1-2 % between seeds, as much as halving
    the mesh did)."""
    if len(rows) <= n:
        return np.arange(len(rows))
    u = np.random.default_rng(seed).random(shape, dtype=np.float32)[rows, cols]
    return np.sort(np.argpartition(u, n)[:n])


class NoShadowInView(ValueError):
    """The predicted shadow boundary does not fall inside the usable part of the photo."""


@dataclasses.dataclass
class PhotoSamples:
    """Pixels of one photo used by the fit.

    uv (n, 2) pixel (col, row); ground (n, 3) receiver points; jac (n, 3, 2) d(point)/d(col, row),
    metres per pixel;
    observed (n,) linear gray; albedo_class (n,) 0 paper / 1 other; uv_norm (n, 2) in
    [-0.5, 0.5]; profile_id (n,) nearest boundary sample; plan: the discrete choices;
    normals (n, 3): the receiver's unit normals at the points (None: the ground plane, +z), which
    the ``wedge`` rule's plan off the plane needs (``fitting.solve.rule_choice.wedge_plan``).
    """

    name: str
    uv: np.ndarray
    ground: np.ndarray
    jac: np.ndarray
    observed: np.ndarray
    albedo_class: np.ndarray
    uv_norm: np.ndarray
    profile_id: np.ndarray
    plan: PointPlan
    n_profiles: int
    band_px: int
    sky_hidden: np.ndarray | None = None  # (n,) sky fraction hidden from each point (``softshadow.sky``)
    sun_cos: np.ndarray | None = None  # (n,) sun incidence over the open ground's (None: 1, the ground)
    normals: np.ndarray | None = None  # (n, 3) the receiver's unit normals (None: the ground plane)


def paper_mask(gray: np.ndarray, exclude: np.ndarray) -> np.ndarray | None:
    """The white sheet (H, W) bool: the convex hulls of large bright, smooth regions, or None.

    Found when the image's brightness is clearly bimodal (paper at least 1.5x the
    ground); the hull closes the parts the shadow hides.
    """
    usable = ~exclude & np.isfinite(gray)
    if usable.sum() < 100:
        return None
    values = gray[usable]
    scale = np.percentile(values, 99.5)
    if not scale > 0:
        return None
    img8 = np.clip(gray / scale * 255, 0, 255).astype(np.uint8)
    thr, _ = cv2.threshold(img8[usable].reshape(-1, 1), 0, 255, cv2.THRESH_BINARY + cv2.THRESH_OTSU)
    bright = (img8 > thr) & usable
    dark_med = np.median(values[values * 255 / scale <= thr]) if np.any(values * 255 / scale <= thr) else 0
    bright_med = np.median(values[values * 255 / scale > thr]) if bright.any() else 0
    if not (bright_med > 1.5 * max(dark_med, 1e-9)):
        return None
    # Smooth: low local variation relative to brightness (paper, not specular clutter).
    blur = cv2.GaussianBlur(gray.astype(np.float32), (0, 0), 2.0)
    var = cv2.GaussianBlur((gray.astype(np.float32) - blur) ** 2, (0, 0), 2.0)
    smooth = np.sqrt(np.maximum(var, 0)) < 0.08 * np.maximum(blur, 1e-9)
    region = (bright & smooth).astype(np.uint8)
    region = cv2.morphologyEx(region, cv2.MORPH_OPEN, np.ones((5, 5), np.uint8))
    n, labels, stats, _ = cv2.connectedComponentsWithStats(region, connectivity=8)
    keep = [i for i in range(1, n) if stats[i, cv2.CC_STAT_AREA] >= 0.002 * gray.size]
    if not keep:
        return None
    hulls = [cv2.convexHull(np.column_stack(np.nonzero(labels == i)[::-1]).astype(np.int32))
             for i in keep]
    mask = np.zeros(gray.shape, np.uint8)
    for hull in _merge_convex_pieces(hulls):
        cv2.fillConvexPoly(mask, hull, 1)
    return mask.astype(bool)


def _merge_convex_pieces(hulls: list[np.ndarray]) -> list[np.ndarray]:
    """Merge hulls that are pieces of one convex sheet: two pieces join when the hull of both
    adds no more area than the smaller piece has (a sheet cut by a shadow joins again; a sheet
    and a calibration board's white margin, with ground between them, do not)."""
    hulls = list(hulls)
    merged = True
    while merged and len(hulls) > 1:
        merged = False
        for i in range(len(hulls)):
            for j in range(i + 1, len(hulls)):
                both = cv2.convexHull(np.vstack([hulls[i], hulls[j]]))
                a, b = cv2.contourArea(hulls[i]), cv2.contourArea(hulls[j])
                if cv2.contourArea(both) - a - b <= min(a, b):
                    hulls[i] = both
                    del hulls[j]
                    merged = True
                    break
            if merged:
                break
    return hulls
