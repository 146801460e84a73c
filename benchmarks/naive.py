"""The naive renderer: every pixel against every silhouette edge (NumPy), for the scaling study.

The same linear-ramp model as the renderer's ``edge`` rule, evaluated by brute force: each
silhouette edge (a lit face beside an unlit one) is projected along the light onto the ground;
every pixel finds its nearest projected edge (a pixels x edges distance table, in chunks), and
alpha = clip(1/2 - s / (2 k d), 0, 1) with s the distance to it (negative inside the hard
shadow) and d the distance along the light from the edge's point to the ground. Its cost is
O(pixels x silhouette edges); the renderer's is O(penumbra pixels + edges).
"""

from __future__ import annotations

import numpy as np

from .shoji import ShojiRenderer

__all__ = ["NaiveRenderer"]


class NaiveRenderer:
    CHUNK = 4_000_000  # pixel-edge pairs per chunk (memory ~ 32 bytes each)

    def __init__(self, mesh):
        self._shoji = ShojiRenderer(mesh)  # silhouette and the hard shadow (the stencil, k = 0)
        self.vertices = self._shoji.vertices

    def silhouette_edges(self, sun_direction) -> int:
        return int(len(self._shoji._silhouette(-np.asarray(sun_direction, np.float64))[1]))

    def render(self, sun_direction, grid, k: float, rho: float) -> np.ndarray:
        light = -np.asarray(sun_direction, dtype=np.float64)
        _, edges, _, _ = self._shoji._silhouette(light)
        hard = self._shoji.stencil(sun_direction, grid, 0.0) >= 1
        v = self.vertices
        ground = v[:, :2] - (v[:, 2] / light[2])[:, None] * light[:2]
        depth = v[:, 2] / -light[2]  # distance along the light to the ground
        a, b = ground[edges[:, 0]], ground[edges[:, 1]]
        da, db = depth[edges[:, 0]], depth[edges[:, 1]]
        ab = b - a
        len2 = np.maximum(np.sum(ab * ab, axis=1), 1e-18)
        pts = grid.pixel_centres().reshape(-1, 3)[:, :2]
        alpha = np.empty(len(pts))
        step = max(1, self.CHUNK // max(len(edges), 1))
        for s in range(0, len(pts), step):
            p = pts[s:s + step]
            u = np.clip(((p[:, None, :] - a[None]) * ab[None]).sum(-1) / len2[None], 0.0, 1.0)
            near = a[None] + u[..., None] * ab[None]
            dist = np.sqrt(np.sum((p[:, None, :] - near) ** 2, axis=-1))
            e = np.argmin(dist, axis=1)
            r = np.arange(len(p))
            width = np.maximum(k * (da[e] + u[r, e] * (db[e] - da[e])), 1e-12)
            signed = np.where(hard.reshape(-1)[s:s + step], -dist[r, e], dist[r, e])
            alpha[s:s + step] = np.clip(0.5 - signed / (2.0 * width), 0.0, 1.0)
        return (1.0 - alpha * (1.0 - rho)).reshape(grid.height, grid.width)
