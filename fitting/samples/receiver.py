"""Samples on a receiver that is not the ground plane: a range image or a mesh (NumPy/OpenCV).

As ``fitting.samples.ground`` does on the plane, the fit looks at a band of pixels
around the predicted hard shadow's boundary, here found on the receiver
itself: every pixel (every f-th on large photos) is back-projected onto the
receiver (``fitting.samples.receiver_points``), the plan decides which of those points
lie in the hard shadow, and the boundary is where that changes between
neighbouring pixels. The band's half-width is the widest penumbra the fit
allows, 2 k_max d / cos(incidence) on the receiver (d: the point's distance to
the occluder's far end along the sun, an upper bound), in pixels.

Left out: the object and its outline, saturated and masked pixels, pixels
where the receiver has no data, creases and depth steps (a pixel there mixes
two faces), faces nearly edge-on to or turned away from the sun, and points the
receiver shadows itself (the model has only the object's shadow).
"""

from __future__ import annotations

import inspect

import cv2
import numpy as np
import trimesh
from scipy.spatial import cKDTree

from softshadow import Pose, SoftShadowModel, Sun
from softshadow.internal import PointPlan, PosedOccluder, object_mask, plan_points

from .receiver_light import sun_incidence
from .receiver_points import ReceiverSurface
from softshadow.internal import open_sky_fraction
from ..photos.views import PhotoView
from .photo_samples import NoShadowInView, PhotoSamples, paper_mask, stable_pick

__all__ = ["select_receiver_samples", "receiver_plan", "MIN_SUN_INCIDENCE", "RECEIVER_SAMPLES_FACTOR"]

MIN_SUN_INCIDENCE = 0.15  # faces lit more obliquely than this (over the ground's) are left out
MAX_POINTS = 600_000      # receiver points planned at once to find the boundary
# A receiver that is not the plane takes this many times the plane's samples per photo: its lit
# level varies with the normal, which costs precision (depth-background, 1600x1200, seed 0: k +15.9 %
# with 1,300 samples a photo, +9.2 % with 4,000; seed 4: rho +0.0107 and +0.0084).
RECEIVER_SAMPLES_FACTOR = 3
CREASE_COS = 0.985        # neighbours whose normals differ by more than ~10 degrees: a crease


def receiver_plan(model: SoftShadowModel, sun: Sun, pose: Pose, points: np.ndarray, normals: np.ndarray,
                  range_k_max: float, pixel_m: float) -> PointPlan:
    """The plan for receiver points (N, 3) anywhere, with their normals (N, 3).

    With the light-space back end (``plan_points(..., normals=...)``) the plan is made
    where the points are. Without it, the discrete choices are made at the points'
    projections along the light onto z = 0 (the same light ray, so the same hard-shadow
    side while the occluder is not between them) and evaluated at the points themselves.
    """
    if "normals" in inspect.signature(plan_points).parameters:
        return model.plan_points(sun, pose, points, range_k_max, pixel_m=pixel_m, normals=normals)
    light = sun.light_np
    ground = points - (points[:, 2] / light[2])[:, None] * light
    return model.plan_points(sun, pose, ground, range_k_max, pixel_m=pixel_m)


def _crease_free(receiver: ReceiverSurface, view: PhotoView, cols, rows, pts, nrm, span: int = 2):
    """Whether each pixel's neighbours +-span pixels away lie on its own plane (N,) bool."""
    h, w = view.shape
    ok = np.ones(len(cols), bool)
    for dc, dr in ((span, 0), (-span, 0), (0, span), (0, -span)):
        c = np.clip(cols + dc, 0, w - 1)
        r = np.clip(rows + dr, 0, h - 1)
        p2, n2, v2, _ = receiver.at_pixels(view, c, r)
        off = np.abs(np.einsum("nj,nj->n", nrm, p2 - pts))
        gap = np.linalg.norm(p2 - pts, axis=1)
        ok &= v2 & (np.einsum("nj,nj->n", nrm, n2) > CREASE_COS) & (off < 0.05 * gap + 1e-4)
    return ok


def _self_lit(blocker: trimesh.Trimesh | None, pts, sun_dir, offset_m: float) -> np.ndarray:
    """Whether each point sees the sun's centre past the receiver itself (N,) bool."""
    if blocker is None or not len(blocker.faces) or not len(pts):
        return np.ones(len(pts), bool)
    d = np.broadcast_to(sun_dir, pts.shape)
    return ~blocker.ray.intersects_any(pts + offset_m * d, d)


def select_receiver_samples(model: SoftShadowModel, pose: Pose, view: PhotoView, receiver: ReceiverSurface,
                            range_k_max: float = 0.03, sun_margin_deg: float = 0.3, max_samples: int = 12000,
                            seed: int = 0, min_band_px: int = 5, max_band_px: int = 80,
                            sky_occlusion: bool = True):
    """Pixels in a band around the predicted shadow boundary on a depth or mesh receiver.

    Returns a ``fitting.samples.photo_samples.PhotoSamples`` (points on the receiver, their normals,
    d(point)/d(pixel), the sky hidden from each point and the sun's incidence on it). Raises NoShadowInView
    when no usable boundary pixel is in the frame.
    """

    h, w = view.shape
    sun = Sun(view.sun_azimuth_deg, view.sun_elevation_deg)
    s_dir = -np.asarray(sun.light_np, dtype=np.float64)
    # Every f-th pixel, back-projected onto the receiver.
    f = max(1, int(np.ceil(np.sqrt(h * w / MAX_POINTS))))
    rr, cc = np.mgrid[0:h:f, 0:w:f]
    pts, nrm, ok, jac = receiver.at_pixels(view, cc.ravel(), rr.ravel())
    exclude = view.saturated.copy() | ~np.isfinite(view.gray)
    if view.ignore is not None:
        exclude |= view.ignore
    obj = object_mask(model.occluder, pose, view.camera)
    exclude |= cv2.dilate(obj.astype(np.uint8), np.ones((5, 5), np.uint8)) > 0
    ok &= ~exclude[rr.ravel(), cc.ravel()]
    if ok.sum() < 50:
        raise NoShadowInView("the receiver is not seen in the photo")
    footprint = np.sqrt(np.abs(np.linalg.norm(np.cross(jac[:, :, 0], jac[:, :, 1]), axis=1)))
    pixel_m = max(float(np.percentile(footprint[ok], 5)) * f, 1e-4)
    plan = receiver_plan(model, sun, pose, pts[ok], nrm[ok], 1e-4, pixel_m)
    hard_img = np.full(rr.shape, -1, np.int8)
    hard_img.ravel()[np.flatnonzero(ok)] = (np.asarray(plan.hard)[:int(ok.sum())] > 0.5).astype(np.int8)
    # The boundary: a receiver pixel in the hard shadow next to a lit one.
    shadow = (hard_img == 1).astype(np.uint8)
    lit = (hard_img == 0).astype(np.uint8)
    cross = np.ones((3, 3), np.uint8)
    boundary = (shadow & cv2.dilate(lit, cross)) | (lit & cv2.dilate(shadow, cross))
    br, bc = np.nonzero(boundary)
    if not len(br):
        raise NoShadowInView("the predicted shadow boundary is not on the receiver in the photo")
    b_index = br * rr.shape[1] + bc
    # Band half-width: the widest penumbra allowed, 2 k d / cos(incidence) on the receiver.
    world = PosedOccluder.make(model.occluder, pose, sun).world
    along = np.max(world @ s_dir) - pts[b_index] @ s_dir  # distance to the occluder's far end
    incidence = np.clip(np.abs(nrm[b_index] @ s_dir), 0.2, 1.0)
    width_m = 2.0 * np.maximum(along, 0.0) / incidence
    px = np.maximum(footprint[b_index], 1e-6)
    half = np.ceil((0.75 * range_k_max * width_m + np.deg2rad(sun_margin_deg) * width_m) / px) + 3
    band_px = int(np.clip(np.percentile(half, 90), min_band_px, max_band_px))
    not_boundary = np.ones((h, w), np.uint8)
    not_boundary[np.minimum(br * f, h - 1), np.minimum(bc * f, w - 1)] = 0
    band = cv2.distanceTransform(not_boundary, cv2.DIST_L2, cv2.DIST_MASK_PRECISE) <= band_px + f
    paper = paper_mask(view.gray, exclude)
    if paper is not None:
        exclude |= cv2.morphologyEx(paper.astype(np.uint8), cv2.MORPH_GRADIENT, np.ones((13, 13), np.uint8)) > 0
    rows, cols = np.nonzero(band & ~exclude)
    # The checks below drop some: keep a few times what is needed (``stable_pick``: a slightly
    # different band keeps the same pixels where it overlaps).
    pick = stable_pick(rows, cols, (h, w), 3 * max_samples, seed)
    rows, cols = rows[pick], cols[pick]
    p, n, v, j = receiver.at_pixels(view, cols, rows)
    v &= _crease_free(receiver, view, cols, rows, p, n)
    sun_cos = sun_incidence(n, s_dir)
    v &= sun_cos >= MIN_SUN_INCIDENCE
    blocker = receiver.blocker_mesh(view.camera)
    v[v] &= _self_lit(blocker, p[v], s_dir, offset_m=max(0.02, 3 * pixel_m))
    rows, cols, p, n, j, sun_cos = rows[v], cols[v], p[v], n[v], j[v], sun_cos[v]
    if len(rows) < 50:
        raise NoShadowInView(f"only {len(rows)} usable receiver pixels near the predicted shadow boundary")
    if len(rows) > max_samples:
        pick = stable_pick(rows, cols, (h, w), max_samples, seed)
        rows, cols, p, n, j, sun_cos = rows[pick], cols[pick], p[pick], n[pick], j[pick], sun_cos[pick]
    b_uv = np.column_stack([bc * f, br * f]).astype(np.float64)
    _, nearest = cKDTree(b_uv).query(np.column_stack([cols, rows]))
    profile_id = nearest // max(1, len(b_uv) // 400)
    sample_m = float(np.median(np.sqrt(np.linalg.norm(np.cross(j[:, :, 0], j[:, :, 1]), axis=1))))
    plan = receiver_plan(model, sun, pose, p, n, range_k_max * 1.5, max(sample_m / 2, 1e-4))
    if sky_occlusion:
        occluder = trimesh.Trimesh(world, model.occluder.faces, process=False)
        blockers = occluder if blocker is None else trimesh.util.concatenate([occluder, blocker])
        sky_hidden = 1.0 - open_sky_fraction(blockers, p, n)
    else:
        sky_hidden = 1.0 - 0.5 * (1.0 + n[:, 2])
    return PhotoSamples(
        name=view.name, uv=np.column_stack([cols, rows]).astype(np.float64), ground=p, jac=j,
        observed=view.gray[rows, cols].astype(np.float64),
        albedo_class=(np.zeros(len(rows), int) if paper is None else (~paper[rows, cols]).astype(int)),
        uv_norm=np.column_stack([cols / w - 0.5, rows / h - 0.5]),
        profile_id=profile_id, plan=plan, n_profiles=int(len(np.unique(profile_id))), band_px=band_px,
        sky_hidden=sky_hidden, sun_cos=sun_cos, normals=n)
