"""High-level rendering: ground maps, camera images and arbitrary receiver points.

``SoftShadowModel`` ties an occluder to an expansion rule and a penumbra
profile. Each call makes its discrete plan in NumPy (``plan``) and evaluates
the differentiable part in JAX; the returned arrays are JAX arrays, so
``jax.grad`` through ``ground_map``/``at_points`` works for ShadowParams, Sun
and Pose (pass concrete values: the plan is made from them).
"""

from __future__ import annotations

import dataclasses
import functools

import cv2
import jax
import jax.numpy as jnp
import numpy as np
import trimesh

from .camera import GroundGrid, PinholeCamera
from .meshes import load_mesh
from .evaluate import plan_alpha
from .occluder import Occluder
from .params import Pose, ShadowParams, Sun
from .penumbra import PROFILES, RULES, shade
from .plan import GridPlan, PointPlan, bucket_size, plan_grid, plan_points
from .posed import posed_vertices

__all__ = ["SoftShadowModel", "CameraRender", "object_mask"]


def _band_k(params: ShadowParams, range_k_max: float | None) -> float:
    if range_k_max is not None:
        return float(range_k_max)
    try:
        return float(params.range_k)
    except jax.errors.ConcretizationTypeError as exc:  # traced k: the band must be given
        raise ValueError("pass range_k_max when k is traced (it sets the penumbra band)") from exc


@functools.partial(jax.jit, static_argnames=("rule", "profile", "shape"))
def _ground_map_core(hard, band_index, origin_x, origin_y, pixel_m, plan: PointPlan, pose: Pose,
                     sun: Sun, params: ShadowParams, rule: str, profile: str, shape):
    dtype = params.rho.dtype
    # Band pixel centres from their flat indices (cheaper than shipping (m, 3) points).
    rows, cols = jnp.divmod(band_index, shape[1])
    points = jnp.stack([origin_x + cols.astype(dtype) * pixel_m, origin_y - rows.astype(dtype) * pixel_m,
                        jnp.zeros(band_index.shape, dtype)], axis=1)
    alpha_band = plan_alpha(points, plan, pose, sun, params.range_k, rule, profile)
    # Padding entries index one past the end and are dropped.
    alpha = hard.reshape(-1).astype(dtype).at[band_index].set(alpha_band.astype(dtype), mode="drop")
    return shade(alpha, params.rho).reshape(shape)


@functools.partial(jax.jit, static_argnames=("rule", "profile"))
def _band_points_core(band_points, band_plan: PointPlan, hard, band_index, pose, sun, params, rule, profile):
    """Shading at all of a plan's points (padded): the hard shadow, with the band points'
    alpha from the penumbra formula scattered in (padding indices are dropped)."""
    dtype = params.rho.dtype
    alpha_band = plan_alpha(band_points, band_plan, pose, sun, params.range_k, rule, profile)
    alpha = hard.astype(dtype).at[band_index].set(alpha_band.astype(dtype), mode="drop")
    return shade(alpha, params.rho)


@functools.partial(jax.jit, static_argnames=("rule", "profile"))
def _points_core(points, plan: PointPlan, pose, sun, params, rule, profile):
    alpha = plan_alpha(points, plan, pose, sun, params.range_k, rule, profile)
    return shade(alpha, params.rho)


@dataclasses.dataclass(frozen=True)
class CameraRender:
    """A camera image of the receiver's shading.

    shading (H, W): 1 - alpha (1 - rho), NaN where the pixel sees no ground;
    object_mask (H, W) bool: the object itself hides the ground there;
    ground_points (H, W, 3): where each pixel's ray meets the receiver.
    """

    shading: jax.Array
    object_mask: np.ndarray
    ground_valid: np.ndarray
    ground_points: np.ndarray


def object_mask(occ: Occluder, pose: Pose, camera: PinholeCamera | GroundGrid) -> np.ndarray:
    """Pixels (H, W) where the posed mesh hides the receiver (NumPy/OpenCV).

    For a top-down ground map, the mesh seen straight down (its footprint from above).
    """
    world, _ = posed_vertices(occ, pose)
    if isinstance(camera, GroundGrid):
        uv, front = camera.to_pixel(world), np.ones(len(world), bool)
    else:
        uv, front = camera.project(world)
    mask = np.zeros((camera.height, camera.width), np.uint8)
    faces = occ.faces[np.all(front[occ.faces], axis=1)]
    tri = np.rint(uv[faces] * 16).astype(np.int64)
    lim = 16 * 4 * max(camera.width, camera.height)
    tri = tri[np.all(np.abs(tri) < lim, axis=(1, 2))].astype(np.int32)
    for t in tri:
        cv2.fillConvexPoly(mask, t, 1, cv2.LINE_8, 4)
    return mask.astype(bool)


@dataclasses.dataclass(frozen=True, eq=False)
class SoftShadowModel:
    """The expanded-shadow-volume soft shadow of one occluder.

    rule: "edge" (default, CONVENTIONS) or "paper" (the seed's vertex normals).
    profile: "linear" (the seed's ramp) or "disk" (occluded fraction of a disk).
    """

    occluder: Occluder
    rule: str = "edge"
    profile: str = "linear"

    def __post_init__(self):
        if self.rule not in RULES:
            raise ValueError(f"unknown expansion rule {self.rule!r}; choose one of {RULES}")
        if self.profile not in PROFILES:
            raise ValueError(f"unknown penumbra profile {self.profile!r}; choose one of {PROFILES}")

    @classmethod
    def from_mesh(cls, mesh: str | trimesh.Trimesh, rule: str = "edge", profile: str = "linear",
                  base_dir=None) -> "SoftShadowModel":
        """From a built-in name, a mesh file path, or a trimesh.Trimesh."""
        if not isinstance(mesh, trimesh.Trimesh):
            mesh = load_mesh(mesh, base_dir)
        return cls(Occluder.from_trimesh(mesh), rule, profile)

    def with_options(self, rule: str | None = None, profile: str | None = None) -> "SoftShadowModel":
        return dataclasses.replace(self, rule=rule or self.rule, profile=profile or self.profile)

    # -- discrete plans (NumPy) -------------------------------------------------------------
    def plan_grid(self, sun: Sun, pose: Pose, grid: GroundGrid, range_k_max: float) -> GridPlan:
        return plan_grid(self.occluder, pose, sun, grid, range_k_max, self.rule,
                         dtype=jnp.result_type(float))

    def plan_points(self, sun: Sun, pose: Pose, points, range_k_max: float, normals=None,
                    **kwargs) -> PointPlan:
        """``softshadow.plan_points`` for this occluder and rule (points anywhere, normals optional)."""
        return plan_points(self.occluder, pose, sun, points, range_k_max, self.rule, normals=normals,
                           **kwargs)

    # -- renders (JAX) -----------------------------------------------------------------------
    def ground_map(self, params: ShadowParams, sun: Sun, pose: Pose, grid: GroundGrid,
                   plan: GridPlan | None = None, range_k_max: float | None = None) -> jax.Array:
        """Shading (H, W) of a top-down ground map: 1 lit, rho in the umbra (linear units).

        Differentiable in params, sun and pose; ``plan`` reuses a plan from
        ``plan_grid`` (it must cover the k you render with).
        """
        if plan is None:
            plan = self.plan_grid(sun, pose, grid, _band_k(params, range_k_max))
        return _ground_map_core(plan.hard, plan.band_index, grid.origin_m[0], grid.origin_m[1],
                                grid.pixel_m, plan.plan, pose, sun, params, self.rule, self.profile,
                                (grid.height, grid.width))

    def at_points(self, params: ShadowParams, sun: Sun, pose: Pose, points, normals=None,
                  plan: PointPlan | None = None, range_k_max: float | None = None,
                  **plan_kwargs) -> jax.Array:
        """Shading (N,) at receiver points (N, 3) anywhere (see ``plan_points``).

        normals (N, 3), optional: points whose surface faces away from the sun are in attached
        shadow (shading rho). The shading is the sun's part only: a tilted receiver's lit level
        (sun incidence, sky) is the brightness model's, not the renderer's. ``plan_kwargs`` go
        to ``plan_points`` (pixel_m, backend, ...). Only the points in a penumbra band are
        evaluated in JAX; the others take the plan's hard shadow.
        """
        points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        if plan is None:
            plan = self.plan_points(sun, pose, points, _band_k(params, range_k_max), normals=normals,
                                    **plan_kwargs)
        n = len(points)
        dtype = jnp.result_type(float)
        if isinstance(plan.active, np.ndarray):  # a concrete plan: evaluate its band points only
            band = np.flatnonzero(plan.active[:n])
            m = len(band)
            size = bucket_size(m)
            take = np.zeros(size, np.int64)
            take[:m] = band
            index = np.full(size, len(plan.hard), np.int64)  # padding: one past the end, dropped
            index[:m] = band
            sub = PointPlan(plan.edges, plan.edge_id[take], plan.hard[take], np.arange(size) < m,
                            plan.near_boundary[take])
            out = _band_points_core(jnp.asarray(points[take], dtype), sub, plan.hard, index, pose, sun,
                                    params, self.rule, self.profile)
            return out[:n]
        size = plan.edge_id.shape[0]
        padded = np.zeros((size, 3))
        padded[:n] = points
        out = _points_core(jnp.asarray(padded, dtype), plan, pose, sun, params, self.rule, self.profile)
        return out[:n]

    def camera_image(self, params: ShadowParams, sun: Sun, pose: Pose,
                     camera: PinholeCamera, range_k_max: float | None = None) -> CameraRender:
        """Shading seen by a pinhole camera, with the object's own mask."""
        rows, cols = np.mgrid[0:camera.height, 0:camera.width]
        ground, valid = camera.ground_points(cols, rows)
        mask = object_mask(self.occluder, pose, camera)
        use = valid & ~mask.ravel()
        pts = ground[use]
        pixel_m = camera.fine_footprint_m(ground, valid, use)
        shading = jnp.full(camera.height * camera.width, jnp.nan)
        if len(pts):
            plan = self.plan_points(sun, pose, pts, _band_k(params, range_k_max), pixel_m=max(pixel_m, 1e-4))
            values = self.at_points(params, sun, pose, pts, plan=plan)
            shading = shading.at[np.flatnonzero(use)].set(values)
        return CameraRender(shading.reshape(camera.height, camera.width), mask,
                            valid.reshape(camera.height, camera.width),
                            ground.reshape(camera.height, camera.width, 3))
