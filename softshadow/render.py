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
from .penumbra import PROFILES, RULES, Profile, Rule, shade
from .plan import GridPlan, PointPlan, bucket_size, plan_grid, plan_points
from .posed import posed_vertices
from .sky import SkyNodes, hidden_sky_nodes

__all__ = ["SoftShadowModel", "CameraRender", "object_mask"]


def _band_k(params: ShadowParams, range_k_max: float | None) -> float:
    if range_k_max is not None:
        return float(range_k_max)
    try:
        return float(params.range_k)
    except jax.errors.ConcretizationTypeError as exc:  # traced k: the band must be given
        raise ValueError("pass range_k_max when k is traced (it sets the penumbra band)") from exc


@functools.partial(jax.jit, static_argnames=("rule", "profile", "shape", "footprint", "corners"))
def _ground_map_core(hard, band_index, origin_x, origin_y, pixel_m, plan: PointPlan, pose: Pose,
                     sun: Sun, params: ShadowParams, sky_hidden, rule: str, profile: str, shape,
                     footprint: bool, corners: bool = False):
    dtype = params.rho.dtype
    # Band pixel centres from their flat indices (cheaper than shipping (m, 3) points).
    rows, cols = jnp.divmod(band_index, shape[1])
    points = jnp.stack([origin_x + cols.astype(dtype) * pixel_m, origin_y - rows.astype(dtype) * pixel_m,
                        jnp.zeros(band_index.shape, dtype)], axis=1)
    # A ground pixel's footprint is the square pixel_m along x and along y.
    axes = jnp.eye(2, 3, dtype=dtype) * jnp.asarray(pixel_m, dtype) if footprint else None
    alpha_band = plan_alpha(points, plan, pose, sun, params.range_k, rule, profile, pixel_axes=axes,
                            corners=corners)
    # Padding entries index one past the end and are dropped.
    alpha = hard.reshape(-1).astype(dtype).at[band_index].set(alpha_band.astype(dtype), mode="drop")
    sky = None if sky_hidden is None else jnp.asarray(sky_hidden, dtype).reshape(-1)
    return shade(alpha, params.rho, sky).reshape(shape)


@functools.partial(jax.jit, static_argnames=("rule", "profile", "corners"))
def _band_points_core(band_points, band_plan: PointPlan, hard, band_index, pose, sun, params, rule, profile,
                      pixel_axes=None, corners: bool = False):
    """Shading at all of a plan's points (padded): the hard shadow, with the band points'
    alpha from the penumbra formula scattered in (padding indices are dropped)."""
    dtype = params.rho.dtype
    alpha_band = plan_alpha(band_points, band_plan, pose, sun, params.range_k, rule, profile, pixel_axes,
                            corners)
    alpha = hard.astype(dtype).at[band_index].set(alpha_band.astype(dtype), mode="drop")
    return shade(alpha, params.rho)


@functools.partial(jax.jit, static_argnames=("rule", "profile", "corners"))
def _points_core(points, plan: PointPlan, pose, sun, params, rule, profile, pixel_axes=None,
                 corners: bool = False):
    alpha = plan_alpha(points, plan, pose, sun, params.range_k, rule, profile, pixel_axes, corners)
    return shade(alpha, params.rho)


def _camera_pixel_axes(ground: np.ndarray, height: int, width: int) -> np.ndarray:
    """Each pixel's footprint on the ground (H*W, 2, 3): the ground offsets across one pixel along
    its columns and rows (central differences of the pixels' ground points, one-sided at the
    image's border)."""
    g = np.asarray(ground, np.float64).reshape(height, width, 3)
    d_col = np.gradient(g, axis=1) if width > 1 else np.zeros_like(g)
    d_row = np.gradient(g, axis=0) if height > 1 else np.zeros_like(g)
    return np.stack([d_col, d_row], axis=2).reshape(-1, 2, 3)


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

    rule: "edge" (default, docs/formats.md), "paper" (the seed's vertex normals), or "wedge" (the
    fraction of the sun's disk the mesh hides, from every silhouette edge near the point, the
    overlaps of the mesh's parts counted once: ``softshadow.wedge``; the same k as ``edge``).
    profile: "linear" (the seed's ramp) or "disk" (occluded fraction of a disk); for ``wedge``,
    the light: the uniform disk of radius tan r = k, or the light whose straight edge casts the
    linear ramp of half-width k.
    footprint: images (``ground_map``) average alpha over each pixel's footprint, in
    penumbra units (``footprint_profile_alpha``), instead of sampling pixel centres
    (default on: a penumbra narrower than a pixel otherwise aliases).
    hidden_sky: images also darken by the sky the object hides, rho h (``softshadow.sky``;
    default on: it is what a camera sees within a few heights of the object). Cast once per
    pose and grid and kept (a few hundred ms for a 64 x 64 node grid); ``at_points`` leaves
    it to the caller.
    corners: near a corner of the shadow's outline, alpha is the light's mass behind the
    corner's wedge (``penumbra.corner_alpha``), not the nearest edge's half-plane. Off by default:
    right at a box's corners (the pillar's band error falls 2-4x) but wrong on the dragon's
    complex outline (band error 0.067 -> 0.17), see docs/renderer.md.
    """

    occluder: Occluder
    rule: Rule = "edge"
    profile: Profile = "linear"
    footprint: bool = True
    hidden_sky: bool = True
    corners: bool = False
    _sky_cache: dict = dataclasses.field(default_factory=dict, init=False, repr=False, compare=False)

    def __post_init__(self):
        if self.rule not in RULES:
            raise ValueError(f"unknown expansion rule {self.rule!r}; choose one of {RULES}")
        if self.profile not in PROFILES:
            raise ValueError(f"unknown penumbra profile {self.profile!r}; choose one of {PROFILES}")

    @classmethod
    def from_mesh(cls, mesh: str | trimesh.Trimesh, rule: Rule = "edge", profile: Profile = "linear",
                  base_dir=None, footprint: bool = True, hidden_sky: bool = True,
                  corners: bool = False) -> "SoftShadowModel":
        """From a built-in name, a mesh file path, or a trimesh.Trimesh."""
        if not isinstance(mesh, trimesh.Trimesh):
            mesh = load_mesh(mesh, base_dir)
        return cls(Occluder.from_trimesh(mesh), rule, profile, footprint, hidden_sky, corners)

    def with_options(self, rule: str | None = None, profile: str | None = None,
                     footprint: bool | None = None, hidden_sky: bool | None = None,
                     corners: bool | None = None) -> "SoftShadowModel":
        return dataclasses.replace(self, rule=rule or self.rule, profile=profile or self.profile,
                                   footprint=self.footprint if footprint is None else footprint,
                                   hidden_sky=self.hidden_sky if hidden_sky is None else hidden_sky,
                                   corners=self.corners if corners is None else corners)

    # -- discrete plans (NumPy) -------------------------------------------------------------
    def plan_grid(self, sun: Sun, pose: Pose, grid: GroundGrid, range_k_max: float) -> GridPlan:
        plan = plan_grid(self.occluder, pose, sun, grid, range_k_max, self.rule,
                         dtype=jnp.result_type(float), footprint=self.footprint)
        if self.hidden_sky:
            plan = dataclasses.replace(plan, sky_hidden=self.sky_map(pose, grid))
        return plan

    def _pose_key(self, pose: Pose) -> bytes:
        return np.asarray([*np.ravel(pose.position), *np.ravel(pose.rotation_deg), pose.scale],
                          np.float64).tobytes()

    def _cached(self, key, make):
        if key not in self._sky_cache:
            if len(self._sky_cache) > 16:
                self._sky_cache.clear()
            self._sky_cache[key] = make()
        return self._sky_cache[key]

    def sky_nodes(self, pose: Pose, fine_m: float = 0.0) -> SkyNodes:
        """The sky fraction the posed object hides from the ground around it (``hidden_sky_nodes``),
        cast once per pose (concrete) and kept."""
        def make():
            world, _ = posed_vertices(self.occluder, pose)
            return hidden_sky_nodes(trimesh.Trimesh(world, self.occluder.faces, process=False), fine_m)
        return self._cached(("nodes", self._pose_key(pose), float(fine_m)), make)

    def sky_map(self, pose: Pose, grid: GroundGrid) -> np.ndarray:
        """The sky fraction h (H, W) the posed object hides from each ground pixel, kept per pose and grid."""
        return self._cached(("map", self._pose_key(pose), grid), lambda: self.sky_nodes(pose, grid.pixel_m).at(
            grid.pixel_centres()).reshape(grid.height, grid.width))

    def plan_points(self, sun: Sun, pose: Pose, points, range_k_max: float, normals=None,
                    **kwargs) -> PointPlan:
        """``softshadow.plan_points`` for this occluder and rule (points anywhere, normals optional)."""
        return plan_points(self.occluder, pose, sun, points, range_k_max, self.rule, normals=normals,
                           **kwargs)

    # -- renders (JAX) -----------------------------------------------------------------------
    def ground_map(self, params: ShadowParams, sun: Sun, pose: Pose, grid: GroundGrid,
                   plan: GridPlan | None = None, range_k_max: float | None = None) -> jax.Array:
        """Shading (H, W) of a top-down ground map: 1 lit, rho in the open umbra (linear units),
        less rho h where the object hides sky (``hidden_sky``), each pixel's alpha averaged over
        its footprint (``footprint``).

        Differentiable in params, sun and pose; ``plan`` reuses a plan from
        ``plan_grid`` (it must cover the k you render with; its hidden sky is held with it).
        """
        if plan is None:
            plan = self.plan_grid(sun, pose, grid, _band_k(params, range_k_max))
        if self.hidden_sky and plan.sky_hidden is None:
            try:
                plan = dataclasses.replace(plan, sky_hidden=self.sky_map(pose, grid))
            except jax.errors.TracerArrayConversionError as exc:
                raise ValueError("with a traced pose, pass a plan from SoftShadowModel.plan_grid "
                                 "(it holds the hidden sky)") from exc
        return _ground_map_core(plan.hard, plan.band_index, grid.origin_m[0], grid.origin_m[1],
                                grid.pixel_m, plan.plan, pose, sun, params,
                                plan.sky_hidden if self.hidden_sky else None, self.rule, self.profile,
                                (grid.height, grid.width), self.footprint, self.corners)

    def at_points(self, params: ShadowParams, sun: Sun, pose: Pose, points, normals=None,
                  plan: PointPlan | None = None, range_k_max: float | None = None,
                  pixel_axes=None, **plan_kwargs) -> jax.Array:
        """Shading (N,) at receiver points (N, 3) anywhere (see ``plan_points``).

        normals (N, 3), optional: points whose surface faces away from the sun are in attached
        shadow (shading rho). The shading is the sun's part only: a tilted receiver's lit level
        (sun incidence, sky) is the brightness model's, not the renderer's. ``plan_kwargs`` go
        to ``plan_points`` (pixel_m, backend, ...). Only the points in a penumbra band are
        evaluated in JAX; the others take the plan's hard shadow. pixel_axes: (2, 3) or (N, 2, 3),
        each point's pixel footprint (offsets in metres across the pixel along its two sides):
        alpha is then averaged over it (``footprint_profile_alpha``), else sampled at the point.
        The sky the object hides is not subtracted here (``camera_image`` and ``ground_map`` do).
        """
        if pixel_axes is not None:
            pixel_axes = np.asarray(pixel_axes, np.float64)
        points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        if plan is None:
            if pixel_axes is not None:  # pixel means are planned (the hard shadow's area in each)
                plan_kwargs = {**plan_kwargs, "pixel_axes": pixel_axes}
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
                            plan.near_boundary[take],
                            None if plan.wedge is None else plan.wedge.select(band, pad_points=size))
            axes = None
            if pixel_axes is not None:
                axes = jnp.asarray(pixel_axes if pixel_axes.ndim == 2 else pixel_axes[take], dtype)
            out = _band_points_core(jnp.asarray(points[take], dtype), sub, plan.hard, index, pose, sun,
                                    params, self.rule, self.profile, axes, self.corners)
            return out[:n]
        size = plan.edge_id.shape[0]
        padded = np.zeros((size, 3))
        padded[:n] = points
        axes = None
        if pixel_axes is not None and pixel_axes.ndim == 3:
            axes = np.zeros((size, 2, 3))
            axes[:n] = pixel_axes
        elif pixel_axes is not None:
            axes = pixel_axes
        out = _points_core(jnp.asarray(padded, dtype), plan, pose, sun, params, self.rule, self.profile,
                           None if axes is None else jnp.asarray(axes, dtype), self.corners)
        return out[:n]

    def camera_image(self, params: ShadowParams, sun: Sun, pose: Pose,
                     camera: PinholeCamera, range_k_max: float | None = None) -> CameraRender:
        """Shading seen by a pinhole camera, with the object's own mask; each pixel's alpha
        averaged over its footprint on the ground (``footprint``) and the sky the object hides
        subtracted (``hidden_sky``), as in ``ground_map``."""
        rows, cols = np.mgrid[0:camera.height, 0:camera.width]
        ground, valid = camera.ground_points(cols, rows)
        mask = object_mask(self.occluder, pose, camera)
        use = valid & ~mask.ravel()
        pts = ground[use]
        pixel_m = camera.fine_footprint_m(ground, valid, use)
        shading = jnp.full(camera.height * camera.width, jnp.nan)
        if len(pts):
            axes = _camera_pixel_axes(ground, camera.height, camera.width)[use] if self.footprint else None
            plan = self.plan_points(sun, pose, pts, _band_k(params, range_k_max), pixel_m=max(pixel_m, 1e-4),
                                    pixel_axes=axes)
            values = self.at_points(params, sun, pose, pts, plan=plan, pixel_axes=axes)
            if self.hidden_sky:
                sky = self.sky_nodes(pose, max(pixel_m, 1e-4)).at(pts)
                values = values - params.rho * jnp.asarray(sky, values.dtype)
            shading = shading.at[np.flatnonzero(use)].set(values)
        return CameraRender(shading.reshape(camera.height, camera.width), mask,
                            valid.reshape(camera.height, camera.width),
                            ground.reshape(camera.height, camera.width, 3))
