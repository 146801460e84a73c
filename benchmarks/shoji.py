"""The Shoji, Murayama and Konno algorithm itself (their section 3.2), as a NumPy/OpenCV baseline.

Not differentiable and not this project's model: the paper's own image-space steps on a top-down
shadow texture of the ground (a ``GroundGrid``), so that its speed and image can be set beside the
renderer's and a physical render's.

1. Shadow volume: silhouette edges (a lit face beside an unlit one) swept to the ground along
   L' = normalize(L + expand N) per silhouette vertex, N = normalize(N1 + N2) of the two faces at
   each silhouette edge, averaged over the vertex's silhouette edges (the paper's rule).
2. Stencil buffer: the volume's faces (the lit cap and the side quadrilaterals), each rasterised
   with +1 where its outward normal faces up and -1 where down (z-pass counting for a camera
   looking down at the ground: every face is in front of it). Stencil >= 1 is shadow.
3. Shadow texture: state -1 (no shadow) everywhere, 1 where the stencil marks shadow.
4. Intensity: the intensity direction is the shadow's direction on the ground (the light's
   horizontal part); the bounding quadrilateral is the axis-aligned box of the state-1 pixels;
   its corners projected on the direction give the start (intensity 0, next to the object) and
   the end (intensity ``range_px``: the increment); pixels outside the box hold -1.
5. Neighbourhood test: each silhouette pixel P(i, j) of the shadow section (state 1 beside
   state -1) with intensity I judges P(i +- I, j +- I): those in the shadow section become soft
   shadow (state 2); the others stay -1.
6. Alpha: linear from 0 on the shadow's outline (next to state -1) to 1 on the hard shadow's
   outline (next to state 1), by the distances to the two; 1 in the hard shadow.
7. Alpha blending: shading = 1 - alpha (1 - rho) (the paper blends its shadow texture of
   brightness 255 rho^(1/2.2) over the image; in linear units this is the project's shading).

So the paper's "range of the soft shadow" is ``range_px``: the width, in shadow-texture pixels, of
the soft band at the far end of the shadow, growing linearly from 0 next to the object. It is a
screen-space quantity: the same sky gives a range proportional to 1 / pixel size.
"""

from __future__ import annotations

import dataclasses

import cv2
import numpy as np
import trimesh

__all__ = ["ShojiTexture", "ShojiRenderer"]


@dataclasses.dataclass(frozen=True)
class ShojiTexture:
    """The shadow texture (H, W): ``state`` (-1 none, 1 hard, 2 soft), ``intensity`` (-1 outside
    the bounding quadrilateral), ``alpha`` (0..1), ``stencil`` (the volume's count)."""

    state: np.ndarray
    intensity: np.ndarray
    alpha: np.ndarray
    stencil: np.ndarray

    def shading(self, rho: float) -> np.ndarray:
        """Alpha blending in linear units: 1 lit, rho in the hard shadow."""
        return 1.0 - self.alpha * (1.0 - rho)


class ShojiRenderer:
    """The paper's algorithm for one mesh (NumPy/OpenCV). The mesh's topology is read once."""

    def __init__(self, mesh: trimesh.Trimesh):
        self.vertices = np.asarray(mesh.vertices, dtype=np.float64)
        self.faces = np.asarray(mesh.faces, dtype=np.int64)
        self.normals = np.asarray(mesh.face_normals, dtype=np.float64)
        self.adjacency = np.asarray(mesh.face_adjacency, dtype=np.int64)            # (E, 2) faces
        self.adjacency_edges = np.asarray(mesh.face_adjacency_edges, dtype=np.int64)  # (E, 2) vertices

    # -- 1. the (expanded) shadow volume -------------------------------------------------------
    def _silhouette(self, light: np.ndarray):
        """Silhouette edges (S, 2) ordered as in their lit face, and that lit face's index (S,)."""
        lit = self.normals @ light < 0.0
        f0, f1 = self.adjacency[:, 0], self.adjacency[:, 1]
        sil = lit[f0] != lit[f1]
        lit_face = np.where(lit[f0[sil]], f0[sil], f1[sil])
        edges = self.adjacency_edges[sil]
        # Order (a, b) as the lit face winds them, so the side quad (b, a, a', b') continues the
        # lit cap's outward orientation.
        tri = self.faces[lit_face]
        pos_a = np.argmax(tri == edges[:, :1], axis=1)
        forward = tri[np.arange(len(tri)), (pos_a + 1) % 3] == edges[:, 1]
        edges = np.where(forward[:, None], edges, edges[:, ::-1])
        other = np.where(lit[f0[sil]], f1[sil], f0[sil])
        return lit, edges, lit_face, other

    def _expanded_light(self, light, edges, lit_face, other, expand: float) -> np.ndarray:
        """L' (V, 3) per vertex: normalize(L + expand N), N the silhouette vertex normal."""
        lights = np.broadcast_to(light, self.vertices.shape).copy()
        if expand == 0.0 or len(edges) == 0:
            return lights
        n_edge = self.normals[lit_face] + self.normals[other]
        n_edge /= np.maximum(np.linalg.norm(n_edge, axis=1, keepdims=True), 1e-12)
        acc = np.zeros_like(self.vertices)
        np.add.at(acc, edges[:, 0], n_edge)
        np.add.at(acc, edges[:, 1], n_edge)
        used = np.unique(edges)
        n_v = acc[used] / np.maximum(np.linalg.norm(acc[used], axis=1, keepdims=True), 1e-12)
        lp = light + expand * n_v
        lights[used] = lp / np.linalg.norm(lp, axis=1, keepdims=True)
        return lights

    # -- 2. the stencil buffer ------------------------------------------------------------------
    @staticmethod
    def _stencil(tris: np.ndarray, grid) -> np.ndarray:
        """Signed count (H, W) of triangles (T, 3, 2) in pixel coordinates over the pixel centres:
        +1 where a triangle whose outward normal faces up covers a centre, -1 for one facing down.

        This is what the stencil buffer accumulates, evaluated by scanlines instead of per
        triangle: every directed triangle edge adds +-1 at the first pixel centre right of where
        it crosses each row of centres (half-open in rows, so a centre on a vertex counts once),
        and a running sum along each row gives every triangle's winding number, summed. Edges
        shared by two faces cancel, so the cost is the rows crossed by the volume's outline.
        """
        h, w = grid.height, grid.width
        a = tris.reshape(-1, 2)
        b = np.roll(tris, -1, axis=1).reshape(-1, 2)
        y0, y1 = a[:, 1], b[:, 1]
        lo = np.clip(np.ceil(np.minimum(y0, y1)), 0, h).astype(np.int64)
        hi = np.clip(np.ceil(np.maximum(y0, y1)), 0, h).astype(np.int64)
        n = hi - lo
        e = np.repeat(np.arange(len(n)), n)
        rows = lo[e] + np.arange(len(e)) - np.repeat(np.cumsum(n) - n, n)
        t = (rows - y0[e]) / (y1[e] - y0[e])
        xc = a[e, 0] + t * (b[e, 0] - a[e, 0])
        cols = np.clip(np.floor(xc) + 1, 0, w).astype(np.int64)
        # Rows grow southwards: an edge going down the rows bounds a region that is
        # counter-clockwise in world xy (outward normal up) on its right, which counts +1.
        step = np.where(y1 > y0, 1, -1)[e]
        flags = np.bincount(rows * (w + 1) + cols, weights=step, minlength=h * (w + 1))
        return np.cumsum(flags.reshape(h, w + 1)[:, :w], axis=1).astype(np.int32)

    def stencil(self, sun_direction: np.ndarray, grid, expand: float) -> np.ndarray:
        """The expanded shadow volume counted in a stencil buffer on ``grid`` (H, W) int32."""
        light = -np.asarray(sun_direction, dtype=np.float64)
        lit, edges, lit_face, other = self._silhouette(light)
        lights = self._expanded_light(light, edges, lit_face, other, expand)
        lam = self.vertices[:, 2] / lights[:, 2]
        ground = self.vertices[:, :2] - lam[:, None] * lights[:, :2]
        ground3 = np.concatenate([ground, np.zeros((len(ground), 1))], axis=1)
        cap = self.vertices[self.faces[lit]]                                   # (C, 3, 3)
        a, b = edges[:, 0], edges[:, 1]
        sides = np.stack([self.vertices[b], self.vertices[a], ground3[a], ground3[b]], axis=1)  # (S, 4, 3)
        to_px = lambda p: grid.to_pixel(p[..., :2])
        # Side quads are swept along two light directions: split into triangles.
        quads = to_px(sides)
        tris = np.concatenate([to_px(cap), quads[:, [0, 1, 2]], quads[:, [0, 2, 3]]], axis=0)
        return self._stencil(tris, grid)

    # -- 3-6. the shadow texture ------------------------------------------------------------------
    @staticmethod
    def texture(stencil: np.ndarray, sun_direction: np.ndarray, range_px: float) -> ShojiTexture:
        """States, intensities and alpha from the stencil (steps 3-6 of the module docstring)."""
        h, w = stencil.shape
        shadow = stencil >= 1
        state = np.where(shadow, 1, -1).astype(np.int8)
        intensity = np.full((h, w), -1, np.int32)
        alpha = shadow.astype(np.float64)
        if not shadow.any() or range_px <= 0:
            return ShojiTexture(state, intensity, alpha, stencil)
        # Intensity direction in pixel coordinates (col right, row down = south).
        d = -np.asarray(sun_direction[:2], dtype=np.float64)
        d = np.array([d[0], -d[1]]) / max(np.hypot(d[0], d[1]), 1e-12)
        rows, cols = np.nonzero(shadow)
        r0, r1, c0, c1 = rows.min(), rows.max(), cols.min(), cols.max()
        corners = np.array([[c0, r0], [c1, r0], [c0, r1], [c1, r1]], np.float64)
        start, end = (corners @ d).min(), (corners @ d).max()
        rr, cc = np.mgrid[r0:r1 + 1, c0:c1 + 1]
        t = ((np.stack([cc, rr], -1) @ d) - start) / max(end - start, 1e-9)
        intensity[r0:r1 + 1, c0:c1 + 1] = np.rint(range_px * t).astype(np.int32)
        # Silhouette pixels: shadow pixels with a 4-neighbour outside the shadow.
        inner = cv2.erode(shadow.astype(np.uint8), cv2.getStructuringElement(cv2.MORPH_CROSS, (3, 3)),
                          borderType=cv2.BORDER_CONSTANT, borderValue=0).astype(bool)
        silhouette = shadow & ~inner
        soft = np.zeros((h, w), bool)
        for level in np.unique(intensity[silhouette]):
            seeds = (silhouette & (intensity == level)).astype(np.uint8)
            size = 2 * int(level) + 1  # P(i +- I, j +- I)
            soft |= cv2.dilate(seeds, np.ones((size, size), np.uint8)).astype(bool)
        soft &= shadow
        state[soft] = 2
        hard = state == 1
        # Linear alpha: 0 on the shadow's outline, 1 on the hard shadow's outline.
        d_out = cv2.distanceTransform((state != -1).astype(np.uint8), cv2.DIST_L2, cv2.DIST_MASK_PRECISE)
        d_in = (cv2.distanceTransform((~hard).astype(np.uint8), cv2.DIST_L2, cv2.DIST_MASK_PRECISE)
                if hard.any() else np.full((h, w), np.inf, np.float32))
        a = (d_out - 0.5) / np.maximum((d_out - 0.5) + (d_in - 0.5), 1e-6)
        alpha = np.where(hard, 1.0, np.where(soft, np.clip(a, 0.0, 1.0), 0.0))
        return ShojiTexture(state, intensity, alpha, stencil)

    def render(self, sun_direction: np.ndarray, grid, range_px: float, rho: float,
               expand: float = 0.0) -> np.ndarray:
        """Soft shadow shading (H, W): the whole algorithm, volume to alpha blending."""
        st = self.stencil(sun_direction, grid, expand)
        return self.texture(st, sun_direction, range_px).shading(rho)

    def render_hard(self, sun_direction: np.ndarray, grid, rho: float) -> np.ndarray:
        """Hard shadow only (the paper's Table 3 "hard shadow"): the stencil, blended."""
        st = self.stencil(sun_direction, grid, 0.0)
        return 1.0 - (st >= 1) * (1.0 - rho)
