"""A camera image of the whole scene lit by an ambient term, the sun and slide projectors.

Every visible point p (``visibility``: the object, receiver meshes and the ground,
flat-shaded) with unit normal n and albedo a (RGB, linear) gets the radiance

    I(p) = a * ( ambient
                 + E_sun * max(0, n . s) * (1 - alpha(p))
                 + sum over projectors of E_j(p) )

- ambient: irradiance from everywhere (the sky, the room), unshadowed;
- the sun: s the unit direction to the sun, E_sun its irradiance on a surface facing
  it, alpha the expanded-shadow-volume model's soft shadow (``SoftShadowModel.at_points``
  with the points' normals: cast, self- and attached shadow) at range k;
- projectors (``projector.Projector``): slide colour, cosine, falloff and a perspective
  shadow map; NumPy, fixed (nothing is fitted there).

On open horizontal ground with a = 1 this is the project's pixel model when
ambient = rho and E_sun = (1 - rho) / sin(elevation) (``SceneLights.from_rho``): lit
ground reads 1, the umbra rho, and I = 1 - alpha (1 - rho) between.

Two steps, as for the rest of the renderer: ``prepare_scene`` (NumPy: what each pixel
sees, the projectors' light, the sun's plan; needs concrete values) and ``shade_scene``
(JAX: differentiable in the ``SceneLights``, the sun and the pose while the plan's choices
hold). ``render_scene`` runs both.
"""

from __future__ import annotations

import dataclasses
import functools
from collections.abc import Sequence

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from .camera import GroundGrid, PinholeCamera
from .occluder import Occluder
from .params import Pose, ShadowParams, Sun, _leaf
from .plan import PointPlan
from .posed import posed_vertices
from .projector import Projector, projector_shadow_map
from .render import SoftShadowModel
from .scratch import Scratch, scratch_array
from .visibility import Surface, VisibleSurfaces, visible_surfaces

__all__ = ["SceneLights", "SceneSetup", "SceneRender", "prepare_scene", "projector_light", "shade_scene",
           "render_scene"]


class SceneLights(eqx.Module):
    """The differentiable light levels (linear irradiance): ambient >= 0; sun_irradiance >= 0 on
    a surface facing the sun; range_k: the sun's soft shadow range k."""

    ambient: Float[Array, ""]
    sun_irradiance: Float[Array, ""]
    range_k: Float[Array, ""]

    def __init__(self, ambient=0.3, sun_irradiance=1.0, range_k=0.01):
        self.ambient = _leaf(ambient)
        self.sun_irradiance = _leaf(sun_irradiance)
        self.range_k = _leaf(range_k)

    @classmethod
    def from_rho(cls, sun: Sun, range_k, rho) -> "SceneLights":
        """Levels that give open horizontal ground the model's shading: lit 1, umbra rho."""
        sin_e = jnp.sin(jnp.deg2rad(sun.elevation_deg))
        return cls(rho, (1.0 - jnp.asarray(rho)) / sin_e, range_k)


@dataclasses.dataclass(frozen=True)
class SceneSetup:
    """The discrete part of a scene render (NumPy).

    visible: what each pixel sees; projector_light (N, 3): the projectors' irradiance at the
    visible points (shadows included); sun_plan: the sun's ``PointPlan`` at those points (None
    without a sun); range_k_max: the k the plan's bands cover.
    """

    visible: VisibleSurfaces
    projector_light: np.ndarray
    sun_plan: PointPlan | None
    range_k_max: float


@dataclasses.dataclass(frozen=True)
class SceneRender:
    """image (H, W, 3) linear radiance (JAX; ``background`` where nothing is seen); setup: the
    discrete part (``setup.visible.surface`` says what each pixel sees)."""

    image: jax.Array
    setup: SceneSetup


def _object_surface(model: SoftShadowModel, pose: Pose, albedo,
                    posed: tuple[np.ndarray, np.ndarray] | None = None) -> Surface:
    """The posed object as a ``Surface``: closed when its mesh is (its back faces are then not
    drawn), with the occluder's face normals turned by the pose. posed: ``posed_vertices``'
    (world, rotation) when already made."""
    occ = model.occluder
    world, rotation = posed_vertices(occ, pose) if posed is None else posed
    closed = _outward(occ) if float(pose.scale) > 0 else False
    return Surface(world, occ.faces, albedo, "object", closed=closed, normals=occ.face_normals @ rotation.T)


@functools.lru_cache(maxsize=64)
def _outward(occ: Occluder) -> bool:
    """Whether the occluder is closed with outward normals (its signed volume positive)."""
    if not occ.watertight:
        return False
    t = occ.vertices[occ.faces]
    return bool(np.einsum("ij,ij->i", t[:, 0], np.cross(t[:, 1], t[:, 2])).sum() > 0)


def caster_face_offsets(surfaces) -> np.ndarray:
    """(len(surfaces) + 1,) int64: where each surface's faces start among the shadow casters' faces
    (the casting surfaces' faces in order), -1 for a surface that casts nothing and in the last
    entry (the ground, surface -1)."""
    offset = np.full(len(surfaces) + 1, -1, np.int64)
    start = 0
    for i, s in enumerate(surfaces):
        if s.casts_shadows:
            offset[i] = start
            start += len(s.faces)
    return offset


def prepare_scene(camera: PinholeCamera | GroundGrid, model: SoftShadowModel, pose: Pose,
                  sun: Sun | None = None, projectors: Sequence[Projector] = (), *,
                  receivers: Sequence[Surface] = (), object_albedo=0.8, ground_albedo=0.8,
                  range_k_max: float = 0.03, smooth: bool = False) -> SceneSetup:
    """The visible surfaces, the projectors' light and the sun's plan (NumPy).

    receivers: further meshes (a wall, steps); ground_albedo None leaves out the ground plane.
    Every mesh casts shadows from the projectors (unless its ``casts_shadows`` is False); from
    the sun only the object does (as in the fitter). range_k_max: the largest k ``shade_scene``
    will be given (it sizes the sun's penumbra bands). smooth: interpolated vertex normals instead
    of flat faces (``visible_surfaces``).
    """
    surfaces = [_object_surface(model, pose, object_albedo), *receivers]
    visible = visible_surfaces(camera, surfaces, ground_albedo, smooth)
    light = projector_light(visible, surfaces, projectors)
    plan = None
    if sun is not None and len(visible.pixel):
        plan = model.plan_points(sun, pose, visible.points, float(range_k_max), normals=visible.normals,
                                 backend="light")
    return SceneSetup(visible, light, plan, float(range_k_max))


def projector_light(visible: VisibleSurfaces, surfaces: Sequence[Surface],
                    projectors: Sequence[Projector], *, scratch: Scratch | None = None) -> np.ndarray:
    """The projectors' irradiance (N, 3) at the visible points, each through its shadow map of
    the surfaces that cast shadows (NumPy); scratch: buffers for the maps and the result. The
    points' own faces (from ``visible``) spare the lookups of points on the nearest face."""
    light = scratch_array(scratch, "projectors.light", (len(visible.pixel), 3))
    light.fill(0.0)
    if not projectors:
        return light
    casters = [s for s in surfaces if s.casts_shadows]
    if casters:
        start = np.cumsum([0] + [len(s.vertices) for s in casters])
        verts = np.vstack([s.vertices for s in casters])
        faces = np.vstack([s.faces + start[i] for i, s in enumerate(casters)])
        facing = np.concatenate([np.full(len(s.faces), -1 if s.closed else 0, np.int8) for s in casters])
    else:
        verts, faces, facing = np.zeros((0, 3)), np.zeros((0, 3), np.int64), np.zeros(0, np.int8)
    points = np.ascontiguousarray(visible.points, np.float64)
    # Each point's face among the casters' faces (-1: the ground, a surface that casts nothing).
    offset = caster_face_offsets(surfaces)
    surface = visible.surface.reshape(-1)[visible.pixel]
    own = offset[surface]  # surface -1 (the ground) takes the last entry, -1
    own = np.where(own >= 0, own + visible.face.reshape(-1)[visible.pixel], -1)
    for j, proj in enumerate(projectors):
        smap = projector_shadow_map(proj, verts, faces, facing=facing, scratch=scratch, name=f"projector{j}")
        proj.add_irradiance(points, visible.normals, smap, light, faces=own)
    return light


def shade_scene(setup: SceneSetup, model: SoftShadowModel, lights: SceneLights, sun: Sun | None = None,
                pose: Pose | None = None, background=0.0) -> jax.Array:
    """The image (H, W, 3) of a prepared scene (JAX; see the module docstring).

    Differentiable in lights, sun and pose (the sun's shadow) while ``setup``'s discrete choices
    hold; pass the same sun and pose as to ``prepare_scene``.
    """
    vis = setup.visible
    h, w = vis.shape
    dtype = jnp.result_type(float)
    normals = jnp.asarray(vis.normals, dtype)
    irradiance = lights.ambient + jnp.asarray(setup.projector_light, dtype)
    if sun is not None and setup.sun_plan is not None:
        pose = Pose() if pose is None else pose
        # rho = 0: the model's shading is then 1 - alpha, the part of the sun the point sees.
        seen = model.at_points(ShadowParams(lights.range_k, 0.0), sun, pose, vis.points, plan=setup.sun_plan)
        cos = jnp.maximum(normals @ (-sun.light).astype(dtype), 0.0)
        irradiance = irradiance + (lights.sun_irradiance * cos * seen)[:, None]
    radiance = jnp.asarray(vis.albedo, dtype) * irradiance
    image = jnp.broadcast_to(jnp.asarray(background, dtype), (h * w, 3))
    return image.at[vis.pixel].set(radiance).reshape(h, w, 3)


def render_scene(camera: PinholeCamera | GroundGrid, model: SoftShadowModel, pose: Pose | None = None,
                 lights: SceneLights | None = None, sun: Sun | None = None,
                 projectors: Sequence[Projector] = (), *, receivers: Sequence[Surface] = (),
                 object_albedo=0.8, ground_albedo=0.8, range_k_max: float | None = None,
                 background=0.0, smooth: bool = False, supersample: int = 1) -> SceneRender:
    """``prepare_scene`` then ``shade_scene``: the scene's image (H, W, 3) in linear radiance.

    lights: default ``SceneLights()`` (ambient 0.3, sun 1, k 0.01); sun None: no sun (ambient
    and projectors only, the Dowling paper's set-up); range_k_max: default max(lights' k, 0.03);
    supersample s: render s x s samples per pixel (a camera of s times the size) and average
    them (anti-aliasing: outlines and facets then cover fractions of pixels); ``setup`` is then
    the fine image's.
    """
    pose = Pose() if pose is None else pose
    lights = SceneLights() if lights is None else lights
    if range_k_max is None:
        range_k_max = max(float(lights.range_k), 0.03)
    s = int(supersample)
    if s < 1:
        raise ValueError(f"supersample must be a whole number >= 1, got {supersample!r}")
    fine = camera if s == 1 else _finer(camera, s)
    setup = prepare_scene(fine, model, pose, sun, projectors, receivers=receivers, object_albedo=object_albedo,
                          ground_albedo=ground_albedo, range_k_max=range_k_max, smooth=smooth)
    image = shade_scene(setup, model, lights, sun, pose, background)
    if s > 1:
        image = image.reshape(camera.height, s, camera.width, s, 3).mean(axis=(1, 3))
    return SceneRender(image, setup)


def _finer(camera: PinholeCamera | GroundGrid, s: int) -> PinholeCamera | GroundGrid:
    """The same view with s x s pixels for each of camera's (pixel centres at the sub-pixels')."""
    if isinstance(camera, GroundGrid):
        shift = 0.5 * (s - 1) / s * camera.pixel_m  # the first sub-pixel's centre from the pixel's
        return GroundGrid(camera.pixel_m / s, (camera.origin_m[0] - shift, camera.origin_m[1] + shift),
                          camera.width * s, camera.height * s)
    return camera.with_size(camera.width * s, camera.height * s)
