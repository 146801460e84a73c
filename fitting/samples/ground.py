"""Choosing the pixels a fit looks at: a band around the predicted shadow boundary (NumPy/OpenCV).

Only pixels near the shadow's edge carry information about k; pixels in the
umbra and on the lit ground fix rho and the lit level. The band is centred on
the hard-shadow boundary predicted from the mesh, pose and sun, and is wide
enough for the largest penumbra allowed (``range_k_max``) plus the sun's
uncertainty. The object itself, saturated pixels and masked pixels are left
out; the albedo class (the white paper against the ground) is found per pixel.
"""

from __future__ import annotations


import cv2
import numpy as np
import trimesh

from softshadow import Pose, SoftShadowModel, Sun
from softshadow.internal import (PosedOccluder, edge_band_widths, object_mask, posed_vertices,
    project_to_ground)

from softshadow.internal import hidden_sky_fraction
from ..photos.views import PhotoView
from .photo_samples import NoShadowInView, PhotoSamples, paper_mask, stable_pick
from .receiver_points import ReceiverSurface

__all__ = ["select_samples"]


def _boundary_ground_points(model: SoftShadowModel, pose: Pose, sun: Sun, spacing_m: float):
    """Points along the projected silhouette (M, 3) and their edge's ground width per unit k."""
    posed = PosedOccluder.make(model.occluder, pose, sun)
    world, light = posed.world, posed.light
    if not posed.n_edges:
        return np.zeros((0, 3)), np.zeros(0), world, light, posed.silhouette
    a, b, outward = posed.edge_geometry("edge")
    ga, gb = project_to_ground(a, light), project_to_ground(b, light)
    n = np.maximum(np.ceil(np.linalg.norm(gb - ga, axis=1) / spacing_m).astype(int), 1) + 1
    seg = np.repeat(np.arange(len(a)), n)
    frac = (np.arange(len(seg)) - np.repeat(np.cumsum(n) - n, n)) / np.repeat(n - 1, n)
    pts2 = ga[seg] + frac[:, None] * (gb[seg] - ga[seg])
    width_per_k = edge_band_widths(a, b, outward, light, 1e-3) / 1e-3
    pts = np.column_stack([pts2, np.zeros(len(pts2))])
    return pts, width_per_k[seg], world, light, posed.silhouette


def select_samples(model: SoftShadowModel, pose: Pose, view: PhotoView, range_k_max: float = 0.03,
                   sun_margin_deg: float = 0.3, max_samples: int = 12000, seed: int = 0,
                   min_band_px: int = 5, max_band_px: int = 80,
                   sky_occlusion: bool = True, albedo: bool = True,
                   mask_model: SoftShadowModel | None = None,
                   sky_model: SoftShadowModel | None = None) -> PhotoSamples:
    """Pixels in a band around the predicted shadow boundary of one photo.

    sky_occlusion: also find, per sample, the sky fraction the object hides (else 0).
    albedo: find the white sheet (``paper_mask``: two albedo classes, the sheet's border left
    out); False: one class, faster (for a look at the shadow alone, ``fitting.solve.lod``).
    mask_model: the object's own pixels are left out with this model's mesh (default ``model``;
    ``fitting.solve.lod`` passes a level of detail, which leaves the object out as well).
    sky_model: the sky the object hides is cast from this model's mesh (default ``model``; on the
    ground plane): an integral over the sky, smooth in the shape, for which ``fitting.solve.lod`` passes a
    coarse level even when the shadow's edges need the full mesh.

    Raises NoShadowInView when no usable boundary pixel is in the frame. A view whose
    receiver is not the plane is sampled on it (``fitting.samples.receiver``).
    """
    receiver: ReceiverSurface | None = view.receiver  # PhotoView, a floor below, cannot name the type
    if receiver is not None and receiver.kind != "plane":
        from .receiver import RECEIVER_SAMPLES_FACTOR, select_receiver_samples
        return select_receiver_samples(model, pose, view, receiver, range_k_max, sun_margin_deg,
                                       RECEIVER_SAMPLES_FACTOR * max_samples, seed, min_band_px, max_band_px,
                                       sky_occlusion)
    h, w = view.shape
    sun = Sun(view.sun_azimuth_deg, view.sun_elevation_deg)
    # Boundary points on the ground, about one image pixel apart.
    mid = view.ground_of_pixels(np.array([w / 2]), np.array([h / 2]))
    probe_jac = mid[2][0] if mid[1][0] else np.eye(2) * 0.005
    spacing = max(float(np.abs(probe_jac).max()), 1e-4)
    bpts, width_per_k, world, light, sil = _boundary_ground_points(model, pose, sun, spacing)
    if not len(bpts):
        raise NoShadowInView("the mesh casts no shadow edge for this sun")
    # Keep only points on the hard shadow's boundary (not silhouette lines inside the shadow).
    plan_b = model.plan_points(sun, pose, bpts, range_k_max=1e-4, pixel_m=spacing)
    on_boundary = np.asarray(plan_b.active)[:len(bpts)]
    uvb, ok = view.project(bpts)
    inside = ok & (uvb[:, 0] >= 0) & (uvb[:, 0] <= w - 1) & (uvb[:, 1] >= 0) & (uvb[:, 1] <= h - 1)
    keep = on_boundary & inside
    if not keep.any():
        raise NoShadowInView("the predicted shadow boundary is outside the photo")
    bpts, uvb, width_per_k = bpts[keep], uvb[keep], width_per_k[keep]
    # Band half-width in pixels: the widest allowed penumbra plus the sun's uncertainty.
    _, _, jac_b = view.ground_of_pixels(uvb[:, 0], uvb[:, 1])
    px_size = np.maximum(np.sqrt(np.abs(np.linalg.det(jac_b))), 1e-6)
    depth = width_per_k / 2.0  # ground width per unit k ~ 2 d
    sun_shift = np.deg2rad(sun_margin_deg) * depth * 2
    half = np.ceil((0.75 * range_k_max * width_per_k + sun_shift) / px_size) + 3
    band_px = int(np.clip(np.percentile(half, 90), min_band_px, max_band_px))
    # The band: pixels within band_px of a boundary point (a distance transform costs the
    # same for any band width; a dilation with a disk of that radius does not).
    not_boundary = np.ones((h, w), np.uint8)
    ib = np.rint(uvb).astype(int)
    not_boundary[ib[:, 1], ib[:, 0]] = 0
    band = cv2.distanceTransform(not_boundary, cv2.DIST_L2, cv2.DIST_MASK_PRECISE) <= band_px
    exclude = view.saturated.copy() | ~np.isfinite(view.gray)
    if view.ignore is not None:
        exclude |= view.ignore
    obj = object_mask((mask_model or model).occluder, pose, view.camera if view.camera is not None else view.grid)
    exclude |= cv2.dilate(obj.astype(np.uint8), np.ones((5, 5), np.uint8)) > 0
    paper = paper_mask(view.gray, exclude) if albedo else None
    if paper is not None:
        # The sheet's own border (+-6 px): there the pixel mixes paper and ground (blur, JPEG
        # ringing) and fits neither class; +-3 px left enough of it to bias a group whose shadow
        # runs along the sheet by 10 %.
        edge = cv2.morphologyEx(paper.astype(np.uint8), cv2.MORPH_GRADIENT, np.ones((13, 13), np.uint8)) > 0
        exclude |= edge
    rows, cols = np.nonzero(band & ~exclude)
    if len(rows) < 50:
        raise NoShadowInView(f"only {len(rows)} usable pixels near the predicted shadow boundary")
    pick = stable_pick(rows, cols, (h, w), max_samples, seed)
    rows, cols = rows[pick], cols[pick]
    ground, valid, jac = view.ground_of_pixels(cols, rows)
    rows, cols, ground, jac = rows[valid], cols[valid], ground[valid], jac[valid]
    # Profile id: the nearest boundary point (every 8th one counts as a profile).
    from scipy.spatial import cKDTree
    _, nearest = cKDTree(uvb).query(np.column_stack([cols, rows]))
    stride = max(1, len(uvb) // 400)
    profile_id = nearest // stride
    plan = model.plan_points(sun, pose, ground, range_k_max=range_k_max * 1.5,
                             pixel_m=float(np.median(px_size)) / 2)
    uv = np.column_stack([cols, rows]).astype(np.float64)
    return PhotoSamples(
        name=view.name, uv=uv, ground=ground, jac=np.concatenate([jac, np.zeros((len(jac), 1, 2))], axis=1),
        observed=view.gray[rows, cols].astype(np.float64),
        albedo_class=(np.zeros(len(rows), int) if paper is None else (~paper[rows, cols]).astype(int)),
        uv_norm=np.column_stack([cols / w - 0.5, rows / h - 0.5]),
        profile_id=profile_id, plan=plan, n_profiles=int(len(np.unique(profile_id))), band_px=band_px,
        sky_hidden=(_hidden_sky(world, model, sky_model, pose, ground) if sky_occlusion else np.zeros(len(ground))))


def _hidden_sky(world: np.ndarray, model: SoftShadowModel, sky_model: SoftShadowModel | None, pose: Pose,
                ground: np.ndarray) -> np.ndarray:
    """The sky fraction (n,) the object hides from each ground point (n, 3), cast from
    ``sky_model``'s mesh when given, else from ``model``'s posed vertices ``world`` (V, 3)."""
    if sky_model is not None:
        world, model = posed_vertices(sky_model.occluder, pose)[0], sky_model
    return hidden_sky_fraction(trimesh.Trimesh(world, model.occluder.faces, process=False), ground)
