"""Scene images at interactive rates: ``render_scene``'s image, forward only (NumPy, compiled loops).

``render_scene`` keeps the sun's soft shadow differentiable (``shade_scene`` is JAX over every
visible pixel). An interactive view needs only the image, so ``render_frame`` draws the same
model with the work a frame needs:

1. what each pixel sees: ``visible_surfaces`` (the z-buffer, back faces of closed meshes culled);
2. each projector's shadow map and light (``Projector.add_irradiance``), as ``render_scene``;
3. the sun's plan at the visible points: ``plan_dense_points``, equal to the ``plan_points``
   that ``render_scene`` makes, kept compact (the hard shadow of every point, a plan of the
   band points only);
4. the expanded-shadow-volume soft shadow in the band: the renderer's own penumbra formula
   (``evaluate.plan_alpha``, JAX, in chunks of fixed sizes), at the band points only;
5. the shading of every visible pixel in one compiled pass (numba)::

       I = albedo * (ambient + projectors + E_sun max(0, n . s) (1 - alpha))

   With a second thread, that thread shades the points out of the shadow's reach (their shadow
   is final once the reach is known) while the first makes the sun's light-space raster, then
   the points within it with their hard shadow and part of step 4's chunks while the first
   evaluates the rest; the band's pixels are shaded again after (the same image).

``FrameRenderer`` keeps what did not change since its last frame (``Scratch.memo``): the posed
object, each projector's shadow map, what each pixel sees while the camera, the surfaces and the
ground stay, and the projectors' light while, besides, the projectors stay; the per-pixel loops
and the z-buffers of large meshes run on two threads (numba, ``parallel_loops``).

The image agrees with ``render_scene``'s (same lights, same ``range_k_max``) to rounding
(tests/test_scene_frame.py). ``range_k_max`` defaults to the lights' own k: the bands are as
narrow as this frame's k allows.
"""

from __future__ import annotations

import dataclasses
import functools
import time
from collections.abc import Sequence
from concurrent.futures import Future, ThreadPoolExecutor

import jax
import numpy as np

from .camera import GroundGrid, PinholeCamera
from .dense_plan import RUN_POINTS, DensePlan, PointBlocks, plan_dense_points
from .evaluate import plan_alpha_jit
from .parallel_loops import loop_helper, parallel_numba
from .params import Pose, Sun
from .plan import EDGE_PADDING, EdgeSet, PointPlan, grid_bucket_size
from .posed import PosedOccluder, posed_vertices
from .projector import Projector, projector_shadow_map
from .render import SoftShadowModel
from .scene_render import SceneLights, _object_surface, caster_face_offsets
from .scratch import Scratch, scratch_array
from .sun import check_sun_above_horizon
from .threads import share
from .visibility import Surface, VisibleSurfaces, visible_surfaces

__all__ = ["FRAME_STEPS", "PENUMBRA_CHUNKS", "FrameRenderer", "SceneFrame", "band_alpha", "render_frame"]

#: The steps ``SceneFrame.milliseconds`` times (wall time; with a second thread, "shading" is the
#: wait for its light and shading (made while this one makes the plan and evaluates the penumbra,
#: "sun_plan" and "sun_band") and the band's pixels shaded again, and "projectors" is not timed;
#: without one, "sun_plan" includes posing the occluder and "projectors" both the shadow maps and
#: the light).
FRAME_STEPS = ("visibility", "projectors", "sun_plan", "sun_band", "shading")


@dataclasses.dataclass(frozen=True)
class SceneFrame:
    """image (H, W, 3) float64 linear radiance (``background`` where nothing is seen); visible:
    what each pixel sees; plan: the sun's ``DensePlan`` (None without a sun); milliseconds: wall
    time per step (``FRAME_STEPS``)."""

    image: np.ndarray
    visible: VisibleSurfaces
    plan: DensePlan | None
    milliseconds: dict


def render_frame(camera: PinholeCamera | GroundGrid, model: SoftShadowModel, pose: Pose | None = None,
                 lights: SceneLights | None = None, sun: Sun | None = None,
                 projectors: Sequence[Projector] = (), *, receivers: Sequence[Surface] = (),
                 object_albedo=0.8, ground_albedo=0.8, range_k_max: float | None = None,
                 background=0.0, scratch: Scratch | None = None,
                 pool: ThreadPoolExecutor | None = None) -> SceneFrame:
    """The scene's image (H, W, 3), linear radiance: ``render_scene``'s, forward only and fast.

    Arguments as ``render_scene``'s (flat shading, one sample per pixel); range_k_max: the k the
    sun's penumbra bands are sized for, default the lights' k. scratch: keep the per-frame
    arrays in these buffers (the frame's arrays are then overwritten by the next frame made
    with them; ``FrameRenderer`` does this); pool: a thread that poses the occluder and makes the
    projectors' shadow maps while this one finds what each pixel sees, then the projectors'
    light while this one makes the sun's plan, the shading of the points out of the shadow's
    reach while this one makes the raster (and half its distance transform), half the
    near-outline test and the edges (``plan_dense_points``), then the shading of the rest and
    part of the penumbra while this one evaluates the other part (work it has not started when
    this one needs it is done here).
    """
    pose = Pose() if pose is None else pose
    lights = SceneLights() if lights is None else lights
    k = float(lights.range_k)
    range_k_max = k if range_k_max is None else float(range_k_max)
    ms: dict[str, float] = {}
    t = time.perf_counter()
    # The posed object, the casters and the projectors' shadow maps are kept between frames while
    # their inputs do not change (``Scratch.memo``): a frame where only the sun moves re-makes none.
    pose_key = tuple(np.asarray(x, np.float64) for x in (pose.position, pose.rotation_deg, pose.scale))
    obj, world, rotation = _memo(scratch, "frame.object", (model, *pose_key, _albedo_of(object_albedo)),
                                 lambda: _posed_object(model, pose, object_albedo))
    surfaces = [obj, *receivers]
    # Neither the posed occluder nor the projectors' shadow maps need what the camera sees: the
    # second thread makes them while this one finds it.
    if sun is not None:
        check_sun_above_horizon(float(sun.elevation_deg))
    posed = None if sun is None else _submit(pool, PosedOccluder.lit_by, model.occluder, world, rotation,
                                             sun.light_np)
    if pool is None and sun is not None:
        t = _lap(ms, "sun_plan", t)
    casters = _memo(scratch, "frame.casters", (obj, *[a for r in receivers for a in (r.vertices, r.faces)],
                                               *[r.casts_shadows for r in receivers], *[r.closed for r in receivers]),
                    lambda: _Casters.of(surfaces))
    maps = _submit(pool, _projector_maps, projectors, casters, scratch)
    if pool is None:
        t = _lap(ms, "projectors", t)
    light = shaded = None
    plan, alpha_band = None, np.zeros(0)
    early: list[tuple[np.ndarray, Future]] = []  # (the points shaded early, the pool's Future)
    try:
        # What each pixel sees (and each point's surface and faces) is kept while the camera, the
        # surfaces and the ground stay: a frame where only the sun or a projector changes keeps it.
        seen_key = (*_camera_key(camera), obj, casters, *[a for r in receivers for a in (r.vertices, r.faces, r.normals)],
                    *[r.closed for r in receivers], ground_albedo is None)
        vis, surface, on_object, own, blocks, flat = _memo(scratch, "frame.visible", seen_key,
                                                           lambda: _seen(camera, surfaces, ground_albedo, casters,
                                                                         scratch))
        n = len(vis.pixel)
        albedos = np.vstack([_albedo_of(ground_albedo), *[s.albedo for s in surfaces]])
        t = _lap(ms, "visibility", t)
        light = _submit(pool, _projector_light, vis, own, projectors, maps, scratch)
        if pool is None:
            t = _lap(ms, "projectors", t, add=True)
        h, w = vis.shape
        image = scratch_array(scratch, "frame.image", (h * w, 3))
        sun_dir = np.zeros(3) if sun is None else -np.asarray(sun.light_np, np.float64)
        unshadowed = (vis.pixel, vis.normals, surface, albedos, float(lights.ambient),
                      float(lights.sun_irradiance) if sun is not None else 0.0, sun_dir)
        reached = None
        if sun is not None and n:
            if pool is not None:
                def reached(cand: np.ndarray, hard: np.ndarray) -> None:
                    # The points out of the shadow's reach have their final (attached) shadow:
                    # the second thread shades them while this one makes the raster and the rest.
                    early.append((cand, pool.submit(_shade_others, (*unshadowed, hard), light, background, image, cand,
                                                                    flat)))
            # The points go into the sun's view while the second thread still finds the silhouette.
            plan = plan_dense_points(model.occluder, pose, sun, vis.points, range_k_max, vis.normals,
                                     rule=model.rule, posed=posed, world=world, faces=on_object, scratch=scratch,
                                     reached=reached, pool=pool, blocks=blocks)
            t = _lap(ms, "sun_plan", t, add=pool is None)
        shading = (*unshadowed, plan.hard if plan is not None else np.zeros(0))
        band = plan.band if plan is not None else np.zeros(0, np.int64)
        if pool is not None and plan is not None:
            # The second thread shades the points in the shadow's reach with their hard shadow (the
            # others it shaded while this one made the plan), then evaluates part of the penumbra
            # (JAX) while this one evaluates the rest; the band's pixels are shaded again with it.
            if early:
                shaded = pool.submit(_shade_listed, shading, light, image, early[0][0], flat)
            else:
                shaded = pool.submit(_shade, shading, light, background, image, band[:0], np.zeros(0), flat)
            alpha_band = band_alpha(plan, vis.points, model, pose, sun, k, scratch=scratch, pool=pool)
            t = _lap(ms, "sun_band", t)
            shaded.result()
            pixel, normals, surface, albedos, ambient, sun_irradiance, sun_dir, _ = shading
            _shade_kernel()[1](pixel, normals, surface, albedos, _result(light), ambient, sun_irradiance, sun_dir, band,
                               alpha_band, image)
        else:
            if plan is not None:
                alpha_band = band_alpha(plan, vis.points, model, pose, sun, k, scratch=scratch)
                t = _lap(ms, "sun_band", t)
            _shade(shading, light, background, image, band, alpha_band, flat)
    finally:
        # The second thread's work finished before anything else uses the buffers (also on an
        # error: the next frame would share them).
        for pending in (posed, maps, light, shaded, *[f for _, f in early]):
            if isinstance(pending, Future):
                pending.exception()
    _lap(ms, "shading", t)
    return SceneFrame(image.reshape(h, w, 3), vis, plan, ms)


class FrameRenderer:
    """``render_frame`` for a stream of frames: the per-frame arrays are kept between frames
    (``softshadow.scratch``: fresh memory costs a fifth of a frame in page faults), so are the
    posed object, the projectors' shadow maps, what each pixel sees and the projectors' light
    while their inputs stay (``Scratch.memo``: arrays by value, other objects such as a
    ``Projector`` by identity; a frame's arrays are read-only, as the next frame may reuse them), and
    a second thread runs the projectors and shades the pixels while the first makes the sun's
    plan and shares the penumbra with it (``render_frame``'s pool). threads: 2 (that second
    thread, and the first's compiled loops on two threads) or 1 (all on one); the images are
    the same.

    ``render(...)`` takes ``render_frame``'s arguments. A frame's arrays (image, visible, plan)
    are overwritten by the next frame: copy what you keep. Not for use from two threads at once.
    """

    def __init__(self, threads: int = 2):
        if threads not in (1, 2):
            raise ValueError(f"FrameRenderer threads must be 1 or 2, got {threads!r}")
        self.threads = threads
        self.scratch = Scratch()
        # The second thread's compiled loops run on it alone: the first thread's use both cores.
        self.pool = ThreadPoolExecutor(1, thread_name_prefix="softshadow-frame",
                                       initializer=_numba_threads, initargs=(1,)) if threads == 2 else None

    def render(self, *args, **kwargs) -> SceneFrame:
        numba = parallel_numba()
        before = numba.get_num_threads()
        _numba_threads(self.threads)
        try:
            return render_frame(*args, **kwargs, scratch=self.scratch, pool=self.pool)
        finally:
            numba.set_num_threads(before)

    def close(self) -> None:
        if self.pool is not None:
            self.pool.shutdown()


@dataclasses.dataclass(frozen=True)
class _Casters:
    """The surfaces that cast the projectors' shadows as one mesh (``projector_light``'s):
    vertices (V, 3), faces (F, 3), facing (F,) int8 (-1 for closed surfaces, for culling), and
    offset (S + 1,): each surface's first face among them (-1: it casts none; the last entry,
    -1, is the ground's, read at index GROUND)."""

    vertices: np.ndarray
    faces: np.ndarray
    facing: np.ndarray
    offset: np.ndarray

    @classmethod
    def of(cls, surfaces: Sequence[Surface]) -> "_Casters":
        casters = [s for s in surfaces if s.casts_shadows]
        if len(casters) == 1:
            verts, faces = casters[0].vertices, casters[0].faces
        elif casters:
            start = np.cumsum([0] + [len(s.vertices) for s in casters])
            verts = np.vstack([s.vertices for s in casters])
            faces = np.vstack([s.faces + start[i] for i, s in enumerate(casters)])
        else:
            verts, faces = np.zeros((0, 3)), np.zeros((0, 3), np.int64)
        facing = (np.concatenate([np.full(len(s.faces), -1 if s.closed else 0, np.int8) for s in casters])
                  if casters else np.zeros(0, np.int8))
        return cls(verts, faces, facing, caster_face_offsets(surfaces))


def _projector_maps(projectors: Sequence[Projector], casters: _Casters, scratch: Scratch | None) -> list:
    """Each projector's shadow map of the casters (``projector_light``'s), kept while neither the
    projector's geometry nor the casters change (the map does not depend on the slide's values)."""
    def make(proj, j):
        return lambda: projector_shadow_map(proj, casters.vertices, casters.faces, facing=casters.facing, threads=2,
                                            scratch=scratch, name=f"projector{j}")

    return [_memo(scratch, f"frame.projector{j}", (casters, proj.position, proj.target, proj.up, float(proj.fov_deg),
                                                   int(proj.shadow_px), *map(int, proj.slide.shape[:2])), make(proj, j))
            for j, proj in enumerate(projectors)]


def _posed_object(model: SoftShadowModel, pose: Pose, albedo) -> tuple[Surface, np.ndarray, np.ndarray]:
    """The posed object as a ``Surface`` (``render_scene``'s), its world vertices (V, 3) and rotation (3, 3)."""
    world, rotation = posed_vertices(model.occluder, pose)
    surface = _object_surface(model, pose, albedo, posed=(world, rotation))
    return surface, world, rotation


def _memo(scratch: Scratch | None, name: str, inputs: tuple, make):
    """``scratch.memo(name, inputs, make)``, or ``make()`` without scratch buffers."""
    return make() if scratch is None else scratch.memo(name, inputs, make)


def _seen(camera: PinholeCamera | GroundGrid, surfaces: Sequence[Surface], ground_albedo, casters: _Casters,
          scratch: Scratch | None) -> tuple[VisibleSurfaces, np.ndarray, np.ndarray, np.ndarray, PointBlocks,
                                            np.ndarray]:
    """What each pixel sees (``visible_surfaces``), and each visible point's surface (GROUND -1,
    the object 0, receivers 1...), its face on the object (-1 elsewhere) and among the shadow
    casters' faces (-1: none), each (N,), in one pass; the runs of visible points' bounds (the sun's
    plan skips those out of the shadow's reach); which runs are flat (B,) bool: one normal, one
    surface and consecutive pixels (the shading reads their normal, surface and pixel once)."""
    vis = visible_surfaces(camera, surfaces, ground_albedo, scratch=scratch, albedo=False, threads=2)
    n = len(vis.pixel)
    surface = scratch_array(scratch, "frame.surface", n, np.int64)
    on_object = scratch_array(scratch, "frame.object_face", n, np.int64)
    own = scratch_array(scratch, "frame.caster_face", n, np.int64)
    _point_faces_kernel()(vis.pixel, vis.surface.reshape(-1), vis.face.reshape(-1), casters.offset, surface,
                          on_object, own)
    blocks = PointBlocks.of(vis.points, vis.normals)
    flat = blocks.uniform.copy()
    _flat_runs_kernel()(vis.pixel, surface, flat)
    return vis, surface, on_object, own, blocks, flat


@functools.cache
def _flat_runs_kernel():
    """Clears flat[r] (runs of ``RUN_POINTS`` points, as ``PointBlocks``) where the run's points
    lie on more than one surface or on pixels that do not follow one another (numba)."""
    numba = parallel_numba()

    @numba.njit(cache=True, nogil=True, parallel=True)
    def kernel(pixel, surface, flat):
        n = pixel.shape[0]
        for r in numba.prange(flat.shape[0]):
            start, end = r * RUN_POINTS, min((r + 1) * RUN_POINTS, n)
            for i in range(start + 1, end):
                if surface[i] != surface[start] or pixel[i] != pixel[start] + (i - start):
                    flat[r] = False

    return kernel


def _camera_key(camera: PinholeCamera | GroundGrid) -> tuple:
    """What of a camera or top-down map decides what its pixels see (``Scratch.memo``'s inputs)."""
    if isinstance(camera, GroundGrid):
        return ("grid", float(camera.pixel_m), *map(float, camera.origin_m), int(camera.width), int(camera.height))
    return ("pinhole", camera.K, camera.R, camera.t, int(camera.width), int(camera.height), camera.dist)


def _projector_light(vis: VisibleSurfaces, own: np.ndarray, projectors: Sequence[Projector], maps,
                     scratch: Scratch | None) -> np.ndarray:
    """``projector_light``: the projectors' irradiance (N, 3) at the visible points through their
    maps (own: each point's face among the casters', -1 none); kept while the visible points, the
    projectors (by identity) and their maps stay."""
    maps = _result(maps)
    # vis by identity stands for own too: both are one kept result of ``_seen`` (comparing own's
    # 307,200 values every frame cost a few tenths of a millisecond).
    return _memo(scratch, "frame.light", (vis, *projectors, *maps), lambda: _light(vis, own, projectors, maps,
                                                                                  scratch))


def _light(vis: VisibleSurfaces, own: np.ndarray, projectors: Sequence[Projector], maps: Sequence,
           scratch: Scratch | None) -> np.ndarray:
    light = scratch_array(scratch, "projectors.light", (len(vis.pixel), 3))
    light.fill(0.0)
    points = np.ascontiguousarray(vis.points, np.float64)
    for proj, smap in zip(projectors, maps):
        proj.add_irradiance(points, vis.normals, smap, light, faces=own)
    return light


@functools.cache
def _point_faces_kernel():
    """Per visible point (numba): its surface, its face on the object (surface 0; else -1), and
    its face among the casters' (offset[surface] + face; -1 where offset is -1)."""
    numba = parallel_numba()

    @numba.njit(cache=True, nogil=True, parallel=True)
    def kernel(pixel, surface_img, face_img, offset, surface, on_object, own):
        last = offset.shape[0] - 1
        for i in numba.prange(pixel.shape[0]):
            s = surface_img[pixel[i]]
            f = face_img[pixel[i]]
            surface[i] = s
            on_object[i] = f if s == 0 else -1
            o = offset[s] if s >= 0 else offset[last]
            own[i] = o + f if o >= 0 else -1

    return kernel


def _numba_threads(n: int) -> None:
    """The compiled loops' threads for the calling thread (numba's setting is per thread)."""
    numba = parallel_numba()
    numba.set_num_threads(min(n, numba.config.NUMBA_NUM_THREADS))


def _submit(pool: ThreadPoolExecutor | None, fn, *args, **kwargs):
    """fn(...) on the pool's thread (a Future), or here and now without a pool."""
    return fn(*args, **kwargs) if pool is None else pool.submit(fn, *args, **kwargs)


def _result(value):
    return value.result() if isinstance(value, Future) else value


#: The penumbra's chunk sizes (points, ascending): the band is evaluated in chunks of the largest
#: and one padded chunk of the smallest size that holds the rest, so the compiled function sees
#: these shapes only (per size of the edge arrays). A band that grows or shrinks as the sun turns
#: then compiles nothing: a compile stalls a frame for about a second. Each call also pays about
#: 0.2 ms and for every edge (their pose; 0.4 ms for 5,000 edges), hence few large chunks.
PENUMBRA_CHUNKS = (1024, 4096, 8192)

#: The shapes ``band_alpha`` has compiled: (edges, chunk, rule, profile, corners, dtype).
_compiled: set = set()


def band_alpha(plan: DensePlan, points: np.ndarray, model: SoftShadowModel, pose: Pose, sun: Sun,
               range_k: float, *, scratch: Scratch | None = None,
               pool: ThreadPoolExecutor | None = None) -> np.ndarray:
    """alpha (m,) at the plan's band points: the model's penumbra formula (``plan_alpha``, JAX).

    The band is evaluated in chunks of fixed sizes (``PENUMBRA_CHUNKS``), its edge arrays padded
    to a quarter above their count (``_edge_capacity``), and with scratch, kept at that size while
    the count fits: after the first frame, a frame compiles nothing whatever its band's size
    (each point's alpha depends on that point alone), nor while the silhouette's edges stay
    within the first frame's capacity. Every chunk size is compiled when the first is. pool: a
    thread that evaluates some of the chunks (after the work it was given before) while this one
    evaluates the others: the same values.
    """
    m = len(plan.band)
    if not m:
        return np.zeros(0)
    large = PENUMBRA_CHUNKS[-1]
    chunks = [(a, large) for a in range(0, m - m % large, large)]
    rest = m % large
    if rest:
        chunks.append((m - rest, next(size for size in PENUMBRA_CHUNKS if size >= rest)))
    total = chunks[-1][0] + chunks[-1][1]
    s = plan.edge_count
    n_edges = _edge_capacity(s) if scratch is None else scratch.capacity("penumbra.edges", s, _edge_capacity)
    # As NumPy arrays in the dtype jit computes in (JAX's device_put of them took 0.4-0.9 ms
    # within a frame, several times a chunk's transfer).
    dtype = jax.dtypes.canonicalize_dtype(np.float64)
    edges = jax.tree_util.tree_map(lambda a: a.astype(dtype) if a.dtype == np.float64 else a,
                                   _padded_edges(plan.edges, s, n_edges))
    pts = scratch_array(scratch, "penumbra.points", (total, 3))
    np.take(points, plan.band, axis=0, out=pts[:m])
    pts[m:] = 0.0
    # The chunks' plans as the whole band's rows, made from the plan's leaves (as jit sees them):
    # a PointPlan's constructor, with its checks, costs a third of a millisecond.
    rows = plan.band_rows(total, dtype)
    treedef = _plan_treedef(edges, rows)
    edge_leaves = jax.tree_util.tree_leaves(edges)

    def chunk(a: int, size: int):
        return jax.tree_util.tree_unflatten(treedef, [*edge_leaves, *(x[a:a + size] for x in rows)])

    key = (n_edges, model.rule, model.profile, bool(model.corners), jax.dtypes.canonicalize_dtype(np.float64))
    for size in PENUMBRA_CHUNKS:  # every chunk shape compiled at once: no compile when the band's size changes
        if (size, *key) not in _compiled:
            inactive = jax.tree_util.tree_unflatten(treedef, [*edge_leaves, *(np.zeros((size, *x.shape[1:]), x.dtype)
                                                                               for x in rows)])
            plan_alpha_jit(np.zeros((size, 3)), inactive, pose, sun, range_k, model.rule, model.profile, None,
                           model.corners).block_until_ready()
            _compiled.add((size, *key))

    def evaluate(part: list) -> list:
        # All chunks dispatched before any is waited for (JAX runs them while this thread goes on).
        pending = [plan_alpha_jit(pts[a:a + size], chunk(a, size), pose, sun, range_k, model.rule, model.profile,
                                  None, model.corners) for a, size in part]
        return [np.asarray(out) for out in pending]

    alpha = np.full(m, np.nan)  # a point no chunk wrote would show
    mine, theirs = _shared(chunks, PENUMBRA_CHUNKS[0]) if pool is not None else (chunks, [])
    # The second thread's chunks (after what it was given before) dispatched beside this one's:
    # XLA runs them one after the other, but neither thread waits to dispatch behind the other.
    if theirs:
        their_alpha, my_alpha = share(pool, lambda: evaluate(theirs), lambda: evaluate(mine))
        done = [*zip(mine, my_alpha), *zip(theirs, their_alpha)]
    else:
        done = list(zip(mine, evaluate(mine)))
    for (a, size), out in done:
        alpha[a:min(a + size, m)] = out[:min(size, m - a)]
    return alpha


#: A band plan's tree structure per structure of its edges (``band_alpha``'s chunks).
_plan_treedefs: dict = {}


def _plan_treedef(edges: EdgeSet, rows: tuple):
    """The tree structure of ``PointPlan(edges, *rows)``, made once per structure of the edges
    (which leaves are None)."""
    key = jax.tree_util.tree_structure(edges)
    if key not in _plan_treedefs:
        _plan_treedefs[key] = jax.tree_util.tree_structure(PointPlan(edges, *rows))
    return _plan_treedefs[key]


def _shared(chunks: list, smallest: int) -> tuple[list, list]:
    """The chunks (start, size) split between two threads, each to the one with fewer points so
    far (this one first); chunks of the smallest size (at most ``smallest`` points) stay with this
    one. The second thread reaches its chunks after its shading: a small chunk handed to it is
    dispatched that late, where this thread dispatches it with its own (measured in one process,
    alternated, the 300-face scene frame took 0.8 ms less keeping its 1,024-point chunk here,
    while the full dragon's 4,096-point chunk still gains from the second thread)."""
    parts: tuple[list, list] = ([], [])
    load = [0, 0]
    for a, size in chunks:
        i = int(load[1] < load[0]) if size > smallest else 0
        parts[i].append((a, size))
        load[i] += size
    return parts


def _edge_capacity(count: int) -> int:
    """The edges the penumbra's arrays hold for ``count`` silhouette edges: a quarter more, on one
    of four sizes per octave (a sun that turns changes the count by a few percent)."""
    return grid_bucket_size(count + count // 4 + 1, 64)


def _padded_edges(edges: EdgeSet, count: int, size: int) -> EdgeSet:
    """The first ``count`` edges (the real ones) padded to ``size`` (>= count) with
    ``EDGE_PADDING``: padding edges are never referenced."""
    if size == len(edges.outward_sign):
        return edges

    def padded(path, a: np.ndarray) -> np.ndarray:
        out = np.empty((size, *a.shape[1:]), a.dtype)
        out[count:] = EDGE_PADDING[path[0].name]
        out[:count] = a[:count]
        return out

    # By field (tree_map, not EdgeSet's constructor and its checks: see band_alpha).
    return jax.tree_util.tree_map_with_path(padded, edges)



_NO_RUNS = np.zeros(0, np.bool_)


def _shade(shading: tuple, light, background, image: np.ndarray, band: np.ndarray, alpha_band: np.ndarray,
           flat: np.ndarray = _NO_RUNS) -> None:
    """The shading pass (``_shade_kernel``) into the flat image (H W, 3), the background first
    where no point is seen; light: the projectors' (N, 3) or the Future of it; flat: the flat runs
    (``_seen``), if known."""
    pixel, normals, surface, albedos, ambient, sun_irradiance, sun_dir, hard = shading
    if len(pixel) < len(image):  # the shading writes every pixel that sees something; the rest is background
        image[:] = np.broadcast_to(np.asarray(background, np.float64), (3,))
    _shade_kernel()[0](pixel, normals, surface, albedos, _result(light), ambient, sun_irradiance, sun_dir, hard, band,
                       alpha_band, False, flat, image)


def _shade_others(shading: tuple, light, background, image: np.ndarray, listed: np.ndarray,
                  flat: np.ndarray = _NO_RUNS) -> None:
    """The shading pass (``_shade_kernel``) of the points not in ``listed`` (ascending), each with
    its hard shadow, into the flat image (H W, 3), the background first where no point is seen."""
    pixel, normals, surface, albedos, ambient, sun_irradiance, sun_dir, hard = shading
    if len(pixel) < len(image):
        image[:] = np.broadcast_to(np.asarray(background, np.float64), (3,))
    _shade_kernel()[0](pixel, normals, surface, albedos, _result(light), ambient, sun_irradiance, sun_dir, hard, listed,
                       np.zeros(0), True, flat, image)


def _shade_listed(shading: tuple, light, image: np.ndarray, listed: np.ndarray,
                  flat: np.ndarray = _NO_RUNS) -> None:
    """The shading pass of the points ``listed``, each with its hard shadow (after ``_shade_others``
    with the same list: every point shaded once)."""
    pixel, normals, surface, albedos, ambient, sun_irradiance, sun_dir, hard = shading
    _shade_kernel()[2](pixel, normals, surface, albedos, _result(light), ambient, sun_irradiance, sun_dir, hard, listed,
                       flat, image)


def _lap(ms: dict, step: str, start: float, add: bool = False) -> float:
    now = time.perf_counter()
    ms[step] = 1e3 * (now - start) + (ms.get(step, 0.0) if add else 0.0)
    return now


@functools.cache
def _shade_kernel():
    """The compiled shading passes (numba): per visible point, its surface's albedo (albedos' row
    surface + 1: the ground's first) times ambient plus the projectors' light plus the sun's,
    E max(0, n . s) (1 - alpha), into the flat image. Returns (shade, patch, shade_listed): shade
    every point, alpha the plan's hard shadow or (points of an ascending list) the list's alpha,
    or with skip_listed the points not in the list only; patch only the band's points, with the
    penumbra formula's alpha (after a shading with an empty band: the same image as one shading
    with it); shade_listed the points in an ascending list with their hard shadow (after
    ``shade`` skipping them: every point shaded once). shade and shade_listed take the flat runs
    (``_seen``; empty: none), whose terms (normal, surface, pixel) they read once a run."""
    numba = parallel_numba()

    @loop_helper(inline=True)
    def terms(k, pixel, normals, surface, albedos, sun_irradiance, sun_dir):
        """Point k's sun term before its shadow, E max(0, n . s), its albedo (3) and its pixel
        less k (at a flat run's first point: every point's of the run)."""
        cos = normals[k, 0] * sun_dir[0] + normals[k, 1] * sun_dir[1] + normals[k, 2] * sun_dir[2]
        s = surface[k] + 1  # the ground (-1) first
        return sun_irradiance * max(cos, 0.0), albedos[s, 0], albedos[s, 1], albedos[s, 2], pixel[k] - k

    @loop_helper(inline=True)
    def point(i, alpha, lit, a0, a1, a2, p0, ambient, light, image):
        """Point i shaded, from its ``terms``."""
        sun = lit * (1.0 - alpha)
        image[p0 + i, 0] = a0 * (ambient + light[i, 0] + sun)
        image[p0 + i, 1] = a1 * (ambient + light[i, 1] + sun)
        image[p0 + i, 2] = a2 * (ambient + light[i, 2] + sun)

    # Parallel over blocks of points, each starting at its first listed point; a flat run's terms
    # read once.
    @numba.njit(cache=True, nogil=True, parallel=True)
    def shade(pixel, normals, surface, albedos, light, ambient, sun_irradiance, sun_dir, hard, listed, alpha_listed,
              skip_listed, flat, image):
        has_sun = hard.shape[0] > 0
        n = pixel.shape[0]
        block = 64 * RUN_POINTS  # whole runs
        for b in numba.prange((n + block - 1) // block):
            lo, hi = b * block, min((b + 1) * block, n)
            j = np.searchsorted(listed, lo)
            for start in range(lo, hi, RUN_POINTS):
                run_flat = flat.shape[0] > 0 and flat[start // RUN_POINTS]
                lit, a0, a1, a2, p0 = terms(start, pixel, normals, surface, albedos, sun_irradiance, sun_dir)
                for i in range(start, min(start + RUN_POINTS, hi)):
                    alpha = hard[i] if has_sun else 1.0  # no sun: E is 0
                    if j < listed.shape[0] and listed[j] == i:
                        j += 1
                        if skip_listed:
                            continue
                        alpha = alpha_listed[j - 1]
                    if not run_flat:
                        lit, a0, a1, a2, p0 = terms(i, pixel, normals, surface, albedos, sun_irradiance, sun_dir)
                    point(i, alpha, lit, a0, a1, a2, p0, ambient, light, image)

    @numba.njit(cache=True, nogil=True, parallel=True)
    def patch(pixel, normals, surface, albedos, light, ambient, sun_irradiance, sun_dir, band, alpha_band, image):
        for j in numba.prange(band.shape[0]):
            i = band[j]
            lit, a0, a1, a2, p0 = terms(i, pixel, normals, surface, albedos, sun_irradiance, sun_dir)
            point(i, alpha_band[j], lit, a0, a1, a2, p0, ambient, light, image)

    @numba.njit(cache=True, nogil=True, parallel=True)
    def shade_listed(pixel, normals, surface, albedos, light, ambient, sun_irradiance, sun_dir, hard, listed, flat,
                     image):
        block = 4096
        for b in numba.prange((listed.shape[0] + block - 1) // block):
            run = -1
            run_flat = False
            lit, a0, a1, a2, p0 = 0.0, 0.0, 0.0, 0.0, 0
            for j in range(b * block, min((b + 1) * block, listed.shape[0])):
                i = listed[j]
                if i // RUN_POINTS != run:
                    run = i // RUN_POINTS
                    run_flat = flat.shape[0] > 0 and flat[run]
                    if run_flat:
                        lit, a0, a1, a2, p0 = terms(run * RUN_POINTS, pixel, normals, surface, albedos,
                                                    sun_irradiance, sun_dir)
                if not run_flat:
                    lit, a0, a1, a2, p0 = terms(i, pixel, normals, surface, albedos, sun_irradiance, sun_dir)
                point(i, hard[i], lit, a0, a1, a2, p0, ambient, light, image)

    return shade, patch, shade_listed


def _albedo_of(value) -> np.ndarray:
    """The ground's albedo (3,) (0 without a ground: no pixel has it then)."""
    return np.zeros(3) if value is None else np.broadcast_to(np.asarray(value, np.float64).reshape(-1), (3,))
