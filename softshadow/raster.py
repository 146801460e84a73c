"""Discrete shadow structure on a ground raster (NumPy/OpenCV).

For a posed mesh and a light direction this rasterises, on a top-down grid of
the receiver plane z = 0:

- the hard shadow H: the union of the faces projected along L (every face of
  an open mesh, the lit faces of a closed one), exact for any mesh;
- the silhouette edges that lie on H's boundary, each drawn with its index;
- for every pixel, the nearest such edge (a Voronoi labelling by distance
  transform) and the distance to it.

These are the discrete choices of the model (which edge governs a point,
inside or outside); the continuous part in ``penumbra`` differentiates
through the governing edge's geometry. Cost: O(faces + pixels).
"""

from __future__ import annotations

import dataclasses

import cv2
import numpy as np

from .camera import GroundGrid

__all__ = ["ShadowRaster", "project_to_ground", "rasterise_shadow"]

_SHIFT = 4  # sub-pixel bits for OpenCV drawing
_ONE = 1 << _SHIFT


def project_to_ground(points: np.ndarray, light: np.ndarray, plane_z: float = 0.0) -> np.ndarray:
    """Project world points (..., 3) along light directions (3,) or (..., 3) onto z = plane_z.

    Returns (..., 2).
    """
    lam = (points[..., 2] - plane_z) / light[..., 2]
    return points[..., :2] - lam[..., None] * light[..., :2]


@dataclasses.dataclass(frozen=True)
class ShadowRaster:
    """The discrete shadow structure on ``grid``.

    hard (H, W) uint8 hard shadow; edge_label (H, W) int32 index of the governing
    silhouette edge (-1 where none exists); boundary_dist_px (H, W) float32
    distance in pixels to the nearest boundary edge pixel.
    """

    grid: GroundGrid
    hard: np.ndarray
    edge_label: np.ndarray
    boundary_dist_px: np.ndarray

    def lookup(self, xy: np.ndarray):
        """(hard, edge_label, boundary distance in metres) at world points (N, 2+), nearest pixel.

        Points outside the raster get hard = 0, label -1 and infinite distance.
        """
        cr = np.rint(self.grid.to_pixel(xy)).astype(np.int64)
        inside = ((cr[:, 0] >= 0) & (cr[:, 0] < self.grid.width) & (cr[:, 1] >= 0)
                  & (cr[:, 1] < self.grid.height))
        c = np.clip(cr[:, 0], 0, self.grid.width - 1)
        r = np.clip(cr[:, 1], 0, self.grid.height - 1)
        hard = np.where(inside, self.hard[r, c], 0)
        label = np.where(inside, self.edge_label[r, c], -1)
        dist = np.where(inside, self.boundary_dist_px[r, c] * self.grid.pixel_m, np.inf)
        return hard, label, dist


def _to_fixed(grid: GroundGrid, xy: np.ndarray) -> np.ndarray:
    return np.rint(grid.to_pixel(xy) * _ONE).astype(np.int32)


def rasterise_shadow(grid: GroundGrid, world_vertices: np.ndarray, faces: np.ndarray,
                     face_mask: np.ndarray, edge_vertex_ids: np.ndarray,
                     light: np.ndarray) -> ShadowRaster:
    """Hard shadow, governing silhouette edge and boundary distance for every pixel of ``grid``.

    world_vertices (V, 3); faces (F, 3); face_mask (F,) which faces to fill;
    edge_vertex_ids (S, 2) the silhouette edges; light (3,) unit, light[2] < 0.
    """
    h, w = grid.height, grid.width
    ground = project_to_ground(world_vertices, light)
    fixed = _to_fixed(grid, ground)
    hard = np.zeros((h, w), np.uint8)
    tris = fixed[faces[face_mask]]
    # Skip faces wholly off the raster; OpenCV clips the rest.
    lo, hi = tris.min(1), tris.max(1)
    on = (hi[:, 0] >= -_ONE) & (lo[:, 0] <= w * _ONE) & (hi[:, 1] >= -_ONE) & (lo[:, 1] <= h * _ONE)
    for tri in tris[on]:
        cv2.fillConvexPoly(hard, tri, 1, cv2.LINE_8, _SHIFT)

    label_img = np.zeros((h, w), np.int32)
    seg = fixed[edge_vertex_ids]  # (S, 2, 2)
    for i, (p, q) in enumerate(seg):
        cv2.line(label_img, (int(p[0]), int(p[1])), (int(q[0]), int(q[1])), i + 1, 1, cv2.LINE_8, _SHIFT)

    kernel = np.ones((3, 3), np.uint8)
    dil = cv2.dilate(hard, kernel, borderType=cv2.BORDER_REPLICATE)
    ero = cv2.erode(hard, kernel, borderType=cv2.BORDER_REPLICATE)
    boundary = cv2.dilate(dil - ero, kernel) > 0
    seeds = boundary & (label_img > 0)
    if not seeds.any():
        return ShadowRaster(grid, hard, -np.ones((h, w), np.int32),
                            np.full((h, w), np.inf, np.float32))
    src = np.where(seeds, 0, 1).astype(np.uint8)
    dist, nearest = cv2.distanceTransformWithLabels(src, cv2.DIST_L2, cv2.DIST_MASK_5,
                                                    labelType=cv2.DIST_LABEL_PIXEL)
    seed_labels = label_img[seeds]  # row-major order, as OpenCV numbers the zero pixels
    edge_label = seed_labels[nearest - 1] - 1
    return ShadowRaster(grid, hard, edge_label.astype(np.int32), dist.astype(np.float32))
