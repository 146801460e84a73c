"""A coarse search for the sun when neither the sun nor the time and site are known (NumPy/OpenCV).

Each candidate sun's hard shadow is drawn into every photo of the group (on the photo's own
receiver: the ground, a range image or a mesh) and judged by the darkening *across its outline*:
the log brightness just outside the outline minus just inside, per small cell of the outline.
Comparing the two sides locally makes the search blind to the ground's own light and dark areas
(a white sheet on asphalt darkens nothing). Two scores follow from the cells: the median times
sqrt(cells) finds the shadow's way and depth on a coarse grid (the whole outline must agree, so
an outline that runs along one sheet edge does not win); a matched count (+1 per cell as dark as
the shadow, -1 per cell with no edge) then tells its length, the elevation, for thin objects.
The guess starts the least-squares fit, which refines the sun with k and rho.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence
from typing import Any

import cv2
import numpy as np
import trimesh

from softshadow import Pose, SoftShadowModel
from softshadow.internal import (Occluder, PosedOccluder, decimate, object_mask, posed_vertices, project_to_ground,
                                 winding_fill)

from .views import PhotoView

__all__ = ["SunGuess", "search_sun"]

#: Width (px) the photos are reduced to: the pillar's shadow in a 640-px photo stays 3-4 px wide.
SEARCH_WIDTH_PX = 320
#: Half-width (px, at SEARCH_WIDTH_PX) of the bands either side of a candidate's outline.
BAND_PX = 2
#: Side (px) of the cells the outline is cut into; each cell's contrast is one vote.
CELL_PX = 12
#: Fewer voting cells than this in every photo and the candidate is not scored (its shadow is
#: out of view or too small to judge).
MIN_CELLS = 4
#: Cells of the ground-shadow raster across the shadow's extent (the footprint of the mesh).
FOOTPRINT_PX = 512
#: The coarse grid (degrees; the azimuth step shrinks for low suns) and the pattern search's steps
#: from its REFINE_BEST best.
COARSE_AZIMUTH_STEP = 10.0
COARSE_ELEVATIONS = tuple(range(8, 88, 4))
REFINE_STEPS = (2.0, 1.0, 0.5, 0.25)
REFINE_BEST = 3
#: Faces the mesh is decimated to for the search (its outline at SEARCH_WIDTH_PX needs no more).
SEARCH_FACES = 2000


_OVERHEAD = np.array([0.0, 0.0, -1.0])  # the light the posed mesh starts with (each candidate re-lights it)


@dataclasses.dataclass(frozen=True)
class SunGuess:
    """The search's best sun: azimuth and elevation (degrees) and its score (outline cells that
    match the shadow's depth less those that do not, over every photo; ``_matched_score``)."""
    azimuth_deg: float
    elevation_deg: float
    score: float


@dataclasses.dataclass(frozen=True)
class _PhotoProbe:
    """One reduced photo: log brightness (h, w), the receiver point of each pixel (h, w, 3)
    and which pixels may vote (h, w) (on the receiver, not the object, not ignored)."""
    log_gray: np.ndarray
    points: np.ndarray
    usable: np.ndarray


def _probe(model: SoftShadowModel, pose: Pose, view: PhotoView, width: int) -> _PhotoProbe | None:
    h, w = view.shape
    scale = min(width / w, 1.0)
    size = (max(int(round(w * scale)), 1), max(int(round(h * scale)), 1))
    gray = cv2.resize(view.gray.astype(np.float32), size, interpolation=cv2.INTER_AREA)
    rows, cols = np.mgrid[0:size[1], 0:size[0]]
    full_c = (cols.ravel() + 0.5) * (w / size[0]) - 0.5
    full_r = (rows.ravel() + 0.5) * (h / size[1]) - 0.5
    receiver: Any = view.receiver  # a ReceiverSurface of fitting.samples, the layer above
    if receiver is not None:
        points, _, valid, _ = receiver.at_pixels(view, full_c, full_r)
    else:
        points, valid, _ = view.ground_of_pixels(full_c, full_r)
    usable = valid.reshape(size[::-1]) & np.isfinite(gray) & (gray > 0)
    obj = object_mask(model.occluder, pose, view.camera if view.camera is not None else view.grid)
    # Pixels next to the object vote neither way: the object's own foot and contact shade would
    # reward any sun whose shadow hugs it (a sun straight overhead).
    obj_small = cv2.resize(obj.astype(np.uint8), size, interpolation=cv2.INTER_NEAREST)
    near = np.ones((4 * BAND_PX + 1, 4 * BAND_PX + 1), np.uint8)
    usable &= cv2.dilate(obj_small, near) == 0
    if view.ignore is not None:
        usable &= cv2.resize(view.ignore.astype(np.uint8), size, interpolation=cv2.INTER_NEAREST) == 0
    if view.saturated is not None:
        usable &= cv2.resize(np.asarray(view.saturated, np.uint8), size, interpolation=cv2.INTER_NEAREST) == 0
    if usable.sum() < 100:
        return None
    log_gray = np.log(np.maximum(gray, 1e-4))
    return _PhotoProbe(log_gray, np.nan_to_num(points).reshape(size[1], size[0], 3), usable)


def _footprint(posed: PosedOccluder):
    """The mesh's hard shadow on the ground z = 0 as a raster: (mask (n, n) bool, origin (2,),
    cell m; cell centres at origin + cell * index). Filled by the winding number of the
    silhouette's fill edges, so that folds of the mesh that overlap in the shadow stay filled."""
    ground = posed.ground_vertices()
    lo, hi = ground.min(0), ground.max(0)
    cell = max(float((hi - lo).max()) / (FOOTPRINT_PX - 2), 1e-6)
    origin = lo - cell
    px = (ground - origin) / cell
    mask = np.zeros((FOOTPRINT_PX, FOOTPRINT_PX), bool)
    for edges, weights in posed.silhouette.fill_edges:
        mask |= winding_fill(mask.shape, px[edges[:, 0]], px[edges[:, 1]], weights)
    return mask, origin, cell


def _in_shadow(probe: _PhotoProbe, footprint, light: np.ndarray) -> np.ndarray:
    """Whether each pixel's receiver point lies in the candidate's hard shadow (h, w) bool: the
    point slid along the light onto the ground falls in the mesh's footprint there (exact on the
    ground; on a wall or steps it errs only for points below the object, rare in a photo of its
    shadow)."""
    mask, origin, cell = footprint
    pts = probe.points.reshape(-1, 3)
    ij = np.rint((project_to_ground(pts, light) - origin) / cell).astype(np.int64)
    n = mask.shape[0]
    inside = np.all((ij >= 0) & (ij < n), axis=1)
    out = np.zeros(len(pts), bool)
    out[inside] = mask[ij[inside, 1], ij[inside, 0]]
    return out.reshape(probe.usable.shape) & probe.usable


def _cell_contrasts(probe: _PhotoProbe, shadow: np.ndarray) -> np.ndarray:
    """Per outline cell, the mean log brightness just outside the outline minus just inside
    (cells,); empty when the outline holds fewer than MIN_CELLS cells with both sides."""
    kernel = np.ones((2 * BAND_PX + 1, 2 * BAND_PX + 1), np.uint8)
    s = shadow.astype(np.uint8)
    inner = shadow & (cv2.erode(s, kernel, borderType=cv2.BORDER_REPLICATE) == 0)
    outer = ~shadow & (cv2.dilate(s, kernel) > 0) & probe.usable
    if inner.sum() < MIN_CELLS or outer.sum() < MIN_CELLS:
        return np.zeros(0)
    h, w = shadow.shape
    cells_across = (w + CELL_PX - 1) // CELL_PX
    n = ((h + CELL_PX - 1) // CELL_PX) * cells_across
    rows, cols = np.nonzero(inner | outer)
    cell = (rows // CELL_PX) * cells_across + cols // CELL_PX
    side = outer[rows, cols]
    value = probe.log_gray[rows, cols]
    n_out = np.bincount(cell[side], minlength=n)
    n_in = np.bincount(cell[~side], minlength=n)
    s_out = np.bincount(cell[side], value[side], n)
    s_in = np.bincount(cell[~side], value[~side], n)
    ok = (n_in >= 2) & (n_out >= 2)
    if ok.sum() < MIN_CELLS:
        return np.zeros(0)
    return s_out[ok] / n_out[ok] - s_in[ok] / n_in[ok]


def _first_score(contrasts: list[np.ndarray]) -> float:
    """The first pass's score: per photo the median cell contrast (the whole outline must agree)
    times sqrt(cells), averaged over the photos that vote."""
    votes = [float(np.median(c)) * math.sqrt(len(c)) for c in contrasts if len(c)]
    return float(np.mean(votes)) if votes else -math.inf


def _matched_score(contrasts: list[np.ndarray], half_depth: list[float]) -> float:
    """The second pass's score: a cell darker inside by the shadow's depth (2 x half_depth, per
    photo, measured at the first pass's best sun) counts +1, a cell with no edge -1, in
    between linearly (clipped to [-2, 1]); summed over cells and photos. An outline longer than
    the shadow pays for every cell beyond it, a shorter one misses the cells it does not reach,
    so that the length of a thin object's shadow (the elevation) is told as well as its way."""
    total = 0.0
    for c, tau in zip(contrasts, half_depth):
        if len(c) and tau > 0:
            total += float(np.clip(c / tau - 1.0, -2.0, 1.0).sum())
    return total


def _contrasts(posed: PosedOccluder, probes: Sequence[_PhotoProbe], azimuth: float,
               elevation: float) -> list[np.ndarray]:
    lit = posed.with_sun(azimuth, elevation)
    footprint = _footprint(lit)
    return [_cell_contrasts(p, _in_shadow(p, footprint, lit.light)) for p in probes]


def search_sun(model: SoftShadowModel, pose: Pose, views: Sequence[PhotoView], *,
               width: int = SEARCH_WIDTH_PX, azimuth_step: float = COARSE_AZIMUTH_STEP,
               elevations: Sequence[float] = COARSE_ELEVATIONS) -> SunGuess:
    """The sun whose hard shadow's outline best matches the group's photos (``SunGuess``).

    A coarse grid of suns (every ``azimuth_step`` degrees, finer for low suns, at ``elevations``)
    scored by the outline's median contrast and refined by pattern search from its REFINE_BEST
    best; that sun sets each photo's shadow depth; every sun tried is scored again by the
    matched count (``_matched_score``), the elevation swept at the best azimuth, and the
    REFINE_BEST best refined again. Every photo votes; a photo that cannot (no receiver in
    view) is left out. Raises ValueError when
    no photo can vote, or when no candidate's shadow is in view."""
    probes = [p for p in (_probe(model, pose, v, width) for v in views) if p is not None]
    if not probes:
        raise ValueError("no photo shows enough of the receiver to search for the sun")
    world, rotation = posed_vertices(model.occluder, pose)
    occluder = model.occluder
    if occluder.n_faces > SEARCH_FACES:  # the outline at SEARCH_WIDTH_PX needs no more
        coarse = decimate(trimesh.Trimesh(np.asarray(world, np.float64), occluder.faces, process=False),
                          SEARCH_FACES)
        occluder, world, rotation = Occluder.from_trimesh(coarse), np.asarray(coarse.vertices), np.eye(3)
    posed = PosedOccluder.lit_by(occluder, np.asarray(world, np.float64), rotation, _OVERHEAD)
    seen: dict[tuple[float, float], list[np.ndarray]] = {}

    def contrasts(az: float, el: float) -> list[np.ndarray]:
        key = (round(az % 360.0, 6), round(el, 6))
        if key not in seen:
            seen[key] = (_contrasts(posed, probes, *key) if 1.0 <= el <= 89.0
                         else [np.zeros(0)] * len(probes))
        return seen[key]

    for el in elevations:
        # A low sun's long shadow turns far across the ground for a small turn of the sun: the
        # azimuth step shrinks with tan(elevation), to 2 deg at the lowest.
        step = float(np.clip(azimuth_step * math.tan(math.radians(el)), 2.0, azimuth_step))
        for az in np.arange(0.0, 360.0, step):
            contrasts(float(az), float(el))

    def climb(start, score) -> tuple[float, float]:
        """Pattern search from ``start``: moves of REFINE_STEPS degrees in azimuth or elevation
        while one improves ``score`` (a thin shadow under a low sun is matched within a degree)."""
        best, value = start, score(start)
        for step in REFINE_STEPS:
            moved = True
            while moved:
                moved = False
                for da, de in ((step, 0.0), (-step, 0.0), (0.0, step), (0.0, -step)):
                    key = (round((best[0] + da) % 360.0, 6), round(best[1] + de, 6))
                    contrasts(*key)
                    if score(key) > value:
                        best, value, moved = key, score(key), True
        return best

    def first_score(key) -> float:
        return _first_score(seen[key])

    starts = sorted(seen, key=first_score, reverse=True)[:REFINE_BEST]
    if first_score(starts[0]) == -math.inf:
        raise ValueError("no sun puts the object's shadow in view of the photos")
    first = max((climb(k, first_score) for k in starts), key=first_score)
    depth_all = np.concatenate([c for c in seen[first] if len(c)])
    half_depth = [0.5 * float(np.median(c if len(c) else depth_all)) for c in seen[first]]

    def matched(key) -> float:
        return _matched_score(seen[key], half_depth)

    for el in np.arange(4.0, 89.0, REFINE_STEPS[0]):
        contrasts(first[0], float(el))
    starts = sorted(seen, key=matched, reverse=True)[:REFINE_BEST]
    best = max((climb(k, matched) for k in starts), key=matched)
    az, el = best
    return SunGuess(float(az), float(el), matched((az, el)))

