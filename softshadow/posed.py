"""The occluder posed in the world and lit by the sun: the one place the discrete steps get
world vertices, the light and the silhouette from a ``Pose`` and a ``Sun`` (NumPy).

Every discrete step (plans, sample selection, the sun search, object masks)
starts here, so they all see the same geometry, and none of them dispatches
eager JAX operations: the pose and sun are read once as NumPy float64.
"""

from __future__ import annotations

import dataclasses

import numpy as np
from scipy.spatial.transform import Rotation

from .occluder import Occluder, Silhouette, silhouette
from .params import Pose, Sun
from .raster import project_to_ground, winding_at_points, winding_count_at_points
from .sun import check_sun_above_horizon, light_direction

__all__ = ["PosedOccluder", "pose_matrix", "posed_vertices"]


def pose_matrix(rotation_deg) -> np.ndarray:
    """Rotation (3, 3) of XYZ Euler angles in degrees (about fixed x, then y, then z), NumPy."""
    return Rotation.from_euler("xyz", np.asarray(rotation_deg, np.float64), degrees=True).as_matrix()


def posed_vertices(occ: Occluder, pose: Pose) -> tuple[np.ndarray, np.ndarray]:
    """World vertices (V, 3) of the posed mesh and its rotation (3, 3), NumPy float64."""
    rotation = pose_matrix(pose.rotation_deg)
    world = float(pose.scale) * occ.vertices @ rotation.T + np.asarray(pose.position, np.float64)
    return world, rotation


@dataclasses.dataclass(frozen=True)
class PosedOccluder:
    """An occluder in the world under one light direction.

    world (V, 3) metres; rotation (3, 3) mesh to world; light (3,) the unit direction the
    light travels (L = -s, L_z < 0); silhouette: its silhouette edges and fill layers.
    """

    occluder: Occluder
    world: np.ndarray
    rotation: np.ndarray
    light: np.ndarray
    silhouette: Silhouette

    @classmethod
    def make(cls, occ: Occluder, pose: Pose, sun: Sun) -> "PosedOccluder":
        """Pose the mesh and find its silhouette; raises SunBelowHorizonError for a low sun."""
        check_sun_above_horizon(float(sun.elevation_deg))
        world, rotation = posed_vertices(occ, pose)
        return cls.lit_by(occ, world, rotation, sun.light_np)

    @classmethod
    def lit_by(cls, occ: Occluder, world: np.ndarray, rotation: np.ndarray,
               light: np.ndarray) -> "PosedOccluder":
        """The already posed mesh (world, rotation) under the light direction ``light`` (3,)."""
        light = np.asarray(light, np.float64)
        return cls(occ, world, rotation, light, silhouette(occ, world, rotation, light))

    def with_sun(self, azimuth_deg: float, elevation_deg: float) -> "PosedOccluder":
        """The same pose under another sun (a search over suns poses the mesh once)."""
        light = light_direction(float(azimuth_deg), float(elevation_deg), np)
        return self.lit_by(self.occluder, self.world, self.rotation, light)

    @property
    def n_edges(self) -> int:
        return len(self.silhouette.vertex_ids)

    def edge_geometry(self, rule: str = "edge") -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Silhouette edges in the world: ends a, b (S, 3) and expansion directions (S, 3).

        The direction is the outward edge normal for the ``edge`` and ``wedge`` rules and the seed's
        normalize(N1 + N2) for the ``paper`` rule.
        """
        sil = self.silhouette
        ids = sil.vertex_ids
        local = sil.paper_normal_local if rule == "paper" else sil.normal_local
        return self.world[ids[:, 0]], self.world[ids[:, 1]], local @ self.rotation.T

    def ground_vertices(self, plane_z: float = 0.0) -> np.ndarray:
        """The vertices' shadows (V, 2) on the plane z = plane_z, along the light."""
        return project_to_ground(self.world, self.light, plane_z)

    def hard_shadow_at(self, points_xy: np.ndarray, projected: np.ndarray | None = None) -> np.ndarray:
        """Whether points (N, 2) lie inside the projected mesh's shadow (N,) bool (exact winding
        test against the projected fill edges; O(points x edges)).

        projected: the vertices (V, 2) under the projection the points are given in; by
        default their shadows on the ground z = 0 (points_xy then ground points); the
        light-space plan passes their (u, v) in the sun's view.
        """
        ground = self.ground_vertices() if projected is None else projected
        inside = np.zeros(len(points_xy), bool)
        for edges, weights in self.silhouette.fill_edges:
            inside |= winding_at_points(points_xy, ground[edges[:, 0]], ground[edges[:, 1]], weights)
        return inside

    def winding_count_at(self, points_xy: np.ndarray, projected: np.ndarray | None = None) -> np.ndarray:
        """The depth complexity (N,) at points (N, 2): how many layers of the mesh the sun's ray
        through each crosses, the sum over the fill layers of their winding counts' magnitudes
        (for a closed mesh, the lit faces' count). ``projected`` as ``hard_shadow_at``."""
        ground = self.ground_vertices() if projected is None else projected
        total = np.zeros(len(points_xy))
        for edges, weights in self.silhouette.fill_edges:
            total += np.abs(winding_count_at_points(points_xy, ground[edges[:, 0]], ground[edges[:, 1]], weights))
        return total
