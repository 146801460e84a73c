"""Level of detail for the fit: model only what the photos can show.

A group is fitted with the coarsest level of detail of the object's mesh whose soft shadow, in
the pixels the fit uses, would move k and rho by at most ``tolerance`` of their standard errors.
The test is the fit's own first-order sensitivity. With J (n, p) the derivatives of the samples'
shading with respect to k, rho and each photo's nuisances (its lit level and brightness
gradient), rows weighted by one over the photo's pixel noise sigma, and delta (n,) the shading
of the level minus the full mesh's (weighted alike), a least-squares fit moves the parameters
by (J^T J)^-1 J^T delta, and their standard errors are sqrt(diag (J^T J)^-1). So the tolerance
is tied to what the photos can show: a sharp, quiet, well-resolved photo keeps more detail, a
coarse or noisy one, or a wide penumbra, lets more go.

The shading is the sun's soft shadow 1 - alpha (1 - rho) at k = ``k_ref``: the k the photos
show, coarsely, one step of the fit's start grid down (a narrower penumbra hides less, so this
errs on the side of detail); rho is the group's starting value. sigma comes from adjacent
pixels (``pixel_noise``): it leaves out the texture and model error that the fit's residuals
also hold, so it is smaller than the fit's residual RMS and the test errs on the side of detail.

The standard errors are the ones the fit states (``fitting.solve.uncertainty``): the statistical part
predicted from the pixel noise, and the systematic floor, which depends only on k and rho and
so is known before the fit. Its part that grows as the penumbra narrows is left out (the
penumbra's width in pixels is known only after the fit) and it is taken at ``k_ref`` (below the
k the photos show): both make the errors smaller, so the test errs on the side of detail.

Levels are the face count halved from the mesh down to ``LOD_COARSEST_FACES``, decimated only
when checked, and kept per mesh across fits (``levels_of_detail``) and on disk beside the
compilation cache (``level_store``): a new process reads a level instead of decimating it. The
choice assumes that a coarser level never hides less: it checks the finest decimated level
first (if it fails, the full mesh is kept after one check), then bisects.

The choice never costs the fit: its samples are the fit's own (``sample_views`` on the full
mesh, with the hidden sky of the level the fit casts it from), handed to the fit when the full
mesh is kept; the shading at every k it needs is one compiled program per photo (saved between
processes with ``saved_programs``); and with ``auto`` the hidden sky is cast from a coarse level.
"""

from __future__ import annotations

import collections
import dataclasses
import hashlib
import math
import os
import tempfile
import threading
from collections.abc import Callable
from pathlib import Path

import numpy as np
import trimesh

from softshadow import Pose, SoftShadowModel, Sun, decimate
from softshadow.internal import Occluder, bucket_size, concatenate_plans, default_cache_dir, plan_alpha

from ..samples.ground import select_samples
from ..samples.photo_samples import PhotoSamples
from .options import sampling_rule
from .uncertainty import LOD_FLOOR, systematic_errors
from ..photos.views import PhotoView

__all__ = ["LOD_MIN_FACES", "LOD_COARSEST_FACES", "LOD_SKY_FACES", "GroupLevel", "LevelCheck", "LodChoice",
           "LevelsOfDetail", "ShadowReference", "fitter_face_counts", "pixel_noise", "choice_samples",
           "levels_of_detail", "level_store"]

#: Meshes with at most this many faces are fitted as they are (a level would save nothing).
LOD_MIN_FACES = 2000
#: The coarsest level tried.
LOD_COARSEST_FACES = 300
#: With ``--lod auto``, the sky the object hides is cast from the level nearest this many faces
#: (at most half the level fitted, at least a quarter of this): an integral over the sky, smooth
#: in the shape.
LOD_SKY_FACES = 5000


def fitter_face_counts(n_faces: int, coarsest: int = LOD_COARSEST_FACES) -> list[int]:
    """Target face counts of the fitter's levels, finest (``n_faces``, the mesh itself) first:
    halved while at least twice ``coarsest``, then ``coarsest``."""
    counts = [int(n_faces)]
    while counts[-1] // 2 >= 2 * coarsest:
        counts.append(counts[-1] // 2)
    if coarsest < counts[-1]:
        counts.append(int(coarsest))
    return counts


@dataclasses.dataclass(frozen=True)
class LevelCheck:
    """One level against the full mesh: its faces, the predicted shifts of k and rho in their
    standard errors (first order), and the RMS shading difference over the pixel noise."""

    faces: int
    shift_k_se: float
    shift_rho_se: float
    rms_over_noise: float

    @property
    def worst(self) -> float:
        return max(self.shift_k_se, self.shift_rho_se)


@dataclasses.dataclass(frozen=True)
class LodChoice:
    """The level a group is fitted with: ``model`` with ``faces`` faces (of ``full_faces``), the
    levels checked (finest first) and a one-line account."""

    model: SoftShadowModel
    faces: int
    full_faces: int
    checks: tuple[LevelCheck, ...]
    reason: str


def pixel_noise(view: PhotoView, samples: PhotoSamples) -> float:
    """The photo's pixel noise over its lit level (relative): the RMS difference of horizontally
    adjacent pixels at the samples over sqrt(2), the largest tenth left out (the shadow's own
    edge, texture edges). A JPEG's smoothing and 8-bit steps make half of those differences
    exactly 0, so a median-based estimate would read no noise at all."""
    rows = samples.uv[:, 1].astype(int)
    cols = samples.uv[:, 0].astype(int)
    ok = cols + 1 < view.shape[1]
    d = np.abs(view.gray[rows[ok], cols[ok] + 1].astype(np.float64) - view.gray[rows[ok], cols[ok]])
    d = np.sort(d[np.isfinite(d)])
    d = d[:int(0.9 * len(d))]
    lit = samples.observed[np.asarray(samples.plan.hard)[:len(samples.observed)] < 0.5]
    level = float(np.percentile(lit, 75)) if len(lit) else float(np.percentile(samples.observed, 90))
    if len(d) < 10 or not np.any(d > 0):
        return 1.0 / 255.0  # nothing measurable: one 8-bit step of the lit level
    return float(np.sqrt(np.mean(d ** 2)) / math.sqrt(2.0)) / max(level, 1e-12)


def choice_samples(model: SoftShadowModel, pose: Pose, views: list[PhotoView], range_k_max: float,
                   max_samples: int, seed: int = 0, mask_model: SoftShadowModel | None = None
                   ) -> tuple[list[PhotoSamples], list[PhotoView]]:
    """Each view's samples as the fit draws them (``select_samples``, same count and seeds) on
    ``model`` (the full mesh), without the sky and the white sheet (the choice needs neither);
    views with no shadow in view are left out. Returns the samples and their views.

    mask_model: the object's pixels are left out with this model's mesh (a level of detail):
    the mask only keeps the object itself out of the samples (dilated by 2 pixels), which a
    coarser mesh does as well for the choice, at a fraction of the cost of rasterising every
    face of the full mesh."""
    samples, used = [], []
    for i, v in enumerate(views):
        try:
            samples.append(select_samples(model, pose, v, range_k_max, max_samples=max_samples, seed=seed + i,
                                          sky_occlusion=False, albedo=False, mask_model=mask_model))
            used.append(v)
        except ValueError:  # NoShadowInView: the fit will say so
            continue
    return samples, used


def _plan(model: SoftShadowModel, pose: Pose, sun: Sun, s: PhotoSamples, range_k_max: float,
          edge_pad_to: int = 16, pad_to: int | None = None):
    """The plan of a photo's sample points as the fit makes it, its points padded to ``pad_to``
    (default a bucket of their count) and its edges to at least ``edge_pad_to`` (so that the
    photos and the levels share one compiled program)."""
    n = len(s.observed)
    px = np.sqrt(np.abs(np.linalg.det(s.jac[:, :2, :])))
    plan = model.plan_points(sun, pose, s.ground, range_k_max=range_k_max,
                             pixel_m=max(float(np.median(px)) / 2, 1e-5))
    edges = max(edge_pad_to, int(np.asarray(plan.edges.outward_sign).shape[0]))
    return concatenate_plans([plan], [n], pad_to=pad_to or bucket_size(n), edge_pad_to=edges)


def _shading_program(points, plan, pose, sun, ks, rho, rule, profile):
    """The sun's shading 1 - alpha (1 - rho) (m, n) at the plan's points for each k of ks (m,)."""
    import jax
    alpha = jax.vmap(lambda k: plan_alpha(points, plan, pose, sun, k, rule, profile))(ks)
    return (1.0 - alpha * (1.0 - rho),)


def _shade_ks(model: SoftShadowModel, pose: Pose, sun: Sun, s: PhotoSamples, plan, ks, rho: float) -> np.ndarray:
    """The sun's shading (m, n) at a photo's sample points for each k of ks (m,): one compiled
    program for all of them (saved between processes, ``saved_programs``)."""
    from .saved_programs import call_saved
    n = len(s.observed)
    size = int(np.asarray(plan.hard).shape[0])
    points = np.zeros((size, 3))
    points[:n] = s.ground
    (out,) = call_saved("fitting.solve.lod.shading", _shading_program, points, plan, pose, sun,
                        np.asarray(ks, np.float64), np.array(rho, np.float64), model.rule, model.profile)
    return np.asarray(out)[:, :n]


def _nuisance_columns(shading: np.ndarray, s: PhotoSamples) -> np.ndarray:
    """The fit's nuisances for one photo as columns (n, c): its lit level per albedo class present
    (the white sheet and the ground, ``initial_params``) and its brightness gradient (u, v), each
    times the shading."""
    classes = [c for c in (0, 1) if np.any(s.albedo_class == c)]
    cols = [shading * (s.albedo_class == c) for c in classes]
    return np.column_stack(cols + [shading * s.uv_norm[:, 0], shading * s.uv_norm[:, 1]])


def _lit_fit_sse(shading: np.ndarray, s: PhotoSamples) -> float:
    """Sum of squares left when the photo's samples are fitted by shading (n,) times its lit levels
    and a brightness gradient (linear least squares), relative to the lit level."""
    a = _nuisance_columns(shading, s)
    coef, *_ = np.linalg.lstsq(a, s.observed, rcond=None)
    r = s.observed - a @ coef
    return float(r @ r) / max(float(np.max(np.abs(coef[:-2]))) ** 2, 1e-300)


class ShadowReference:
    """The full mesh's shading at a group's samples and the fit's first-order sensitivity there;
    ``check`` compares a level with it, in the standard errors the fit states (``se``: the
    statistical ``se_stat`` and the systematic ``se_sys``, in quadrature).

    full: the full mesh's model (the fit's rule and profile); views, samples: the group's views
    with a shadow and their samples (the fit's own, ``sample_views``, or ``choice_samples``);
    rho: the starting rho; range_k_max: the largest k the fit searches. k_ref: the k compared
    at; by default the k the photos show, coarsely (the best of the fit's own start grid, 9
    values log-spaced from 5e-4 to range_k_max, each photo's levels and gradient fitted
    linearly), one grid step down (the narrower penumbra hides less, so this errs on the side
    of detail). The shading at all of these k (and at k_ref +- 2 %, for the derivative) is one
    compiled call per photo.
    """

    def __init__(self, full: SoftShadowModel, pose: Pose, views: list[PhotoView], samples: list[PhotoSamples],
                 rho: float, range_k_max: float, k_ref: float | None = None):
        self.pose, self.samples, self.rho = pose, samples, float(rho)
        self.sigmas = [pixel_noise(v, s) for v, s in zip(views, samples)]
        self.suns = [Sun(v.sun_azimuth_deg, v.sun_elevation_deg) for v in views]
        # The samples' own plans (``select_samples`` planned them on the full mesh for 1.5
        # range_k_max), all padded alike (the photos' largest bucket of points and of edges): one
        # compiled program serves every photo and level.
        self.size = max(bucket_size(len(s.observed)) for s in samples)
        self.edge_pad = max(bucket_size(int(np.asarray(s.plan.edges.outward_sign).shape[0]), 16) for s in samples)
        plans = [concatenate_plans([s.plan], [len(s.observed)], pad_to=self.size, edge_pad_to=self.edge_pad)
                 for s in samples]
        grid = np.geomspace(5e-4, range_k_max, 9)
        step = grid[1] / grid[0]
        # Every k a reference can be taken at (one grid step below each grid value), each with
        # its neighbours at +- 2 % for the derivative; then the grid itself.
        refs = grid / step if k_ref is None else np.array([float(k_ref)])
        ks = np.concatenate([np.stack([refs * 0.98, refs, refs * 1.02], 1).ravel(), grid])
        shaded = [_shade_ks(full, pose, sun, s, plan, ks, rho) for sun, s, plan in zip(self.suns, samples, plans)]
        if k_ref is None:
            sse = [sum(_lit_fit_sse(sh[3 * len(refs) + i], s) for sh, s in zip(shaded, samples))
                   for i in range(len(grid))]
            best = int(np.argmin(sse))
        else:
            best = 0
        self.k_ref = float(refs[best])
        self.ks = ks
        self._ref_index = 3 * best + 1
        eps = 0.02 * self.k_ref
        self.ref, rows = [], []
        n_photos = len(samples)
        offsets = np.cumsum([0] + [_nuisance_columns(np.zeros(len(s.observed)), s).shape[1] for s in samples])
        for p, (sh, s) in enumerate(zip(shaded, samples)):
            lo, mid, hi = sh[3 * best], sh[3 * best + 1], sh[3 * best + 2]
            self.ref.append(mid)
            # Columns: k, rho, then per photo its levels and brightness gradient (u, v), as the
            # fit has them (``fitting.solve.model``); rows weighted by 1 / sigma.
            block = np.zeros((len(s.observed), 2 + int(offsets[-1])))
            block[:, 0] = (hi - lo) / (2 * eps)
            block[:, 1] = (1.0 - mid) / max(1.0 - rho, 1e-9)  # d shading / d rho = alpha
            block[:, 2 + offsets[p]:2 + offsets[p + 1]] = _nuisance_columns(mid, s)
            rows.append(block / self.sigmas[p])
        del n_photos
        self.jacobian = np.concatenate(rows)
        self.cov = np.linalg.pinv(self.jacobian.T @ self.jacobian)
        #: Statistical standard errors of (k, rho) predicted from the pixel noise.
        self.se_stat = np.sqrt(np.maximum(np.diag(self.cov)[:2], 1e-300))
        # The stated errors (``fitting.solve.uncertainty.combine_errors``): the systematic floor the
        # tolerance was measured with (LOD_FLOOR) at k_ref without its narrow-penumbra part, both
        # smaller than what the fit will state, in quadrature with the statistical part.
        self.se_sys = np.array(systematic_errors(self.k_ref, self.rho, float("inf"), LOD_FLOOR))
        self.se = np.hypot(self.se_stat, self.se_sys)

    def check(self, faces: int, model: SoftShadowModel) -> LevelCheck:
        """``model`` (a level with ``faces`` faces) against the full mesh (its shading by the same
        compiled program as the reference's)."""
        delta = []
        for sun, s, r, sg in zip(self.suns, self.samples, self.ref, self.sigmas):
            plan = _plan(model, self.pose, sun, s, 1.2 * self.k_ref, self.edge_pad, self.size)
            delta.append((_shade_ks(model, self.pose, sun, s, plan, self.ks, self.rho)[self._ref_index] - r) / sg)
        delta = np.concatenate(delta)
        shift = self.cov @ (self.jacobian.T @ delta)
        return LevelCheck(int(faces), float(abs(shift[0]) / self.se[0]), float(abs(shift[1]) / self.se[1]),
                          float(np.sqrt(np.mean(delta ** 2))))


@dataclasses.dataclass(frozen=True)
class GroupLevel:
    """What ``LevelsOfDetail.for_group`` decides for one group: the model fitted and its face
    count; sky_model: the model the hidden sky is cast from (None: the fitted one); samples: the
    samples the choice drew for these views on the full mesh, as the fit draws them (the views'
    names, then ``sample_views``' samples, views and warnings: ``fit_group``'s ``samples``), when
    it kept the full mesh, else None; check: how far a level the user forced moves k and rho
    against the full mesh (None: not forced, or nothing to compare)."""

    model: SoftShadowModel
    faces: int
    sky_model: SoftShadowModel | None = None
    samples: tuple | None = None
    check: LevelCheck | None = None


class LevelsOfDetail:
    """The object's levels of detail for a folder's fit, decimated once when first needed and
    shared by its groups; ``for_group`` gives one group's model under ``FitOptions.lod``.

    mesh: the object's mesh as given; model: its SoftShadowModel (the fit's rule). Levels are
    built under a lock; ``for_group`` is called under the folder's lock (``fitting.folder.api``).
    """

    def __init__(self, mesh: trimesh.Trimesh, model: SoftShadowModel):
        self.mesh = mesh
        self.full_faces = len(model.occluder.faces)
        self._models: dict[int, tuple[int, SoftShadowModel]] = {self.full_faces: (self.full_faces, model)}
        self._lock = threading.Lock()  # kept between fits (``levels_of_detail``), which may run in threads

    @property
    def full(self) -> SoftShadowModel:
        return self._models[self.full_faces][1]

    def level(self, target: int) -> tuple[int, SoftShadowModel]:
        """(faces, model) of the level decimated to about ``target`` faces (the full mesh when
        it has no more); decimated and built once."""
        target = min(int(target), self.full_faces)
        with self._lock:
            if target not in self._models:
                faces, occluder = _stored_occluder(self.mesh, target)
                self._models[target] = (faces, dataclasses.replace(self.full, occluder=occluder))
            return self._models[target]

    def sky_level(self, faces: int) -> SoftShadowModel | None:
        """The model the hidden sky is cast from when ``faces`` faces are fitted: the fitter's
        level (``fitter_face_counts``) nearest ``LOD_SKY_FACES`` among those with at most half of
        ``faces`` and at least a quarter of ``LOD_SKY_FACES``; None (the fitted level itself) when
        there is none. The hidden sky is the
        fraction of the sky the object covers seen from each ground point, a solid angle that a
        level with 0.5 % less volume changes by about as much, while the shadow's edges can
        need every face (the benchmark checks k and rho against ``--lod off``)."""
        counts = [c for c in fitter_face_counts(self.full_faces) if 2 * c <= faces and 4 * c >= LOD_SKY_FACES]
        if not counts or self.full_faces <= LOD_MIN_FACES:
            return None
        return self.level(min(counts, key=lambda c: abs(math.log(c / LOD_SKY_FACES))))[1]

    def choose(self, reference: ShadowReference, tolerance: float, profile: str | None = None,
               log: Callable[[str], None] | None = None) -> LodChoice:
        """The coarsest level whose checks (``ShadowReference.check``) are at most ``tolerance``:
        the finest decimated level first (when it fails, the full mesh), then bisection."""
        counts = fitter_face_counts(self.full_faces)
        checks: dict[int, LevelCheck] = {}

        def passes(i: int) -> bool:
            if i == 0:
                return True
            faces, model = self.level(counts[i])
            c = reference.check(faces, model.with_options(profile=profile))
            checks[i] = c
            if log:
                log(f"level of detail {faces} faces: k moves {c.shift_k_se:.3g} se, rho {c.shift_rho_se:.3g} se")
            return c.worst <= tolerance

        best = 0
        if len(counts) > 1 and passes(1):
            lo, hi = 1, len(counts)  # counts[lo] passes; counts[hi] (if any) fails
            while hi - lo > 1:
                mid = (lo + hi) // 2
                lo, hi = (mid, hi) if passes(mid) else (lo, mid)
            best = lo
        faces, model = self.level(counts[best])
        reason = (f"{faces} of {self.full_faces} faces: the coarsest level that moves k and rho by at most "
                  f"{tolerance:g} of their standard errors (first order, k = {reference.k_ref:.4g})")
        return LodChoice(model, faces, self.full_faces, tuple(checks[i] for i in sorted(checks)), reason)

    def for_group(self, pose: Pose, views: list[PhotoView], options) -> GroupLevel:
        """The level one group is fitted with under ``options`` (a FitOptions: ``lod``,
        ``lod_tolerance``), the model its hidden sky is cast from, (when the automatic choice keeps
        the full mesh) the samples it drew, for the fit to use, and (for a level the user forced
        below the mesh's face count) how far it moves k and rho against the full mesh
        (``ShadowReference.check``), which the rule book judges."""
        lod = options.lod
        if lod == "off" or (lod == "auto" and self.full_faces <= LOD_MIN_FACES):
            return GroupLevel(self.full, self.full_faces)
        if lod != "auto":
            faces, model = self.level(int(lod))
            if faces >= self.full_faces:
                return GroupLevel(model, faces)
            reference = self._forced_reference(pose, views, options)
            check = None if reference is None else reference.check(faces, model.with_options(
                profile=options.profiles[0]))
            return GroupLevel(model, faces, check=check)
        sky = self.sky_level(self.full_faces)
        if any(v.sun_source == "fitted" for v in views):
            # The sun moves during the fit: no fixed shadow to compare.
            return GroupLevel(self.full, self.full_faces, sky)
        from .group import sample_views
        # The fit's own samples on the full mesh (its hidden sky from the coarse level it will be
        # cast from): the choice's reference, and the fit's samples when the full mesh is kept.
        samples, used, warnings = sample_views(self.full, pose, views, options, sky)
        drawn = (tuple(v.name for v in views), samples, used, warnings)
        if not samples:
            return GroupLevel(self.full, self.full_faces, sky, drawn)  # the fit says why
        profile = options.profiles[0]
        reference = self._reference(pose, used, samples, options)
        log = (lambda line: print(f"  {line}")) if options.verbose else None
        choice = self.choose(reference, options.lod_tolerance, profile, log)
        if choice.faces == self.full_faces:
            return GroupLevel(self.full, self.full_faces, sky, drawn)
        return GroupLevel(choice.model, choice.faces, self.sky_level(choice.faces))

    def _forced_reference(self, pose: Pose, views: list[PhotoView], options) -> ShadowReference | None:
        """The full mesh's shadow in one group's samples (``ShadowReference``), or None when there is
        no fixed shadow to compare (the sun is fitted) or none in view (the fit says so)."""
        if any(v.sun_source == "fitted" for v in views):
            return None  # the sun moves during the fit: no fixed shadow to compare
        counts = fitter_face_counts(self.full_faces)
        # The object's mask from the finest decimated level, which the choice checks first anyway.
        samples, used = choice_samples(self.full, pose, views, options.range_k_max,
                                       options.max_samples_per_photo, options.seed,
                                       mask_model=self.level(counts[1])[1] if len(counts) > 1 else None)
        return self._reference(pose, used, samples, options) if samples else None

    def _reference(self, pose: Pose, used: list[PhotoView], samples, options) -> ShadowReference:
        """The full mesh's shadow (under the fit's first profile) in these samples of ``used``."""
        from .group import initial_params
        return ShadowReference(self.full.with_options(profile=options.profiles[0]), pose, used, samples,
                               initial_params(samples)[1], options.range_k_max)


#: Meshes whose levels are kept between fits (``levels_of_detail``), most recent last.
_KEPT_MESHES = 4
_kept: collections.OrderedDict = collections.OrderedDict()
_kept_lock = threading.Lock()


def _mesh_key(mesh: trimesh.Trimesh, rule: str) -> str:
    h = hashlib.sha1()
    for a in (np.ascontiguousarray(mesh.vertices, np.float64), np.ascontiguousarray(mesh.faces, np.int64)):
        h.update(a.tobytes())
    return f"{h.hexdigest()}:{rule}"


def levels_of_detail(mesh: trimesh.Trimesh, rule: str = "edge") -> LevelsOfDetail:
    """The ``LevelsOfDetail`` of ``mesh`` under expansion ``rule``, kept (by the mesh's vertices
    and faces) for the next fit of the same mesh, up to ``_KEPT_MESHES`` meshes: building the
    full mesh's occluder (0.3 s for the 41k-face dragon) and decimating a level (0.1-0.2 s) are
    paid once per process, not once per fit."""
    rule = sampling_rule(rule)  # the wedge and auto fits sample (and choose levels) with the edge rule
    key = _mesh_key(mesh, rule)
    with _kept_lock:
        if key in _kept:
            _kept.move_to_end(key)
            return _kept[key]
    lods = LevelsOfDetail(mesh, SoftShadowModel.from_mesh(mesh, rule=rule))
    with _kept_lock:
        lods = _kept.setdefault(key, lods)
        while len(_kept) > _KEPT_MESHES:
            _kept.popitem(last=False)
    return lods


def _levels_dir() -> Path | None:
    cache = default_cache_dir()
    return None if cache is None else cache / "levels"


#: Part of the stored levels' names: a new value when ``decimate``'s output changes, so that
#: levels stored by an older version are not read.
_LEVEL_FORMAT = 2


def _level_path(mesh: trimesh.Trimesh, faces: int, kind: str) -> Path | None:
    directory = _levels_dir()
    return None if directory is None else \
        directory / f"{_mesh_key(mesh, 'mesh')[:40]}-{int(faces)}-{kind}-{_LEVEL_FORMAT}.npz"


def _read(path: Path | None) -> dict | None:
    if path is None:
        return None
    try:
        with np.load(path) as data:
            return {k: data[k] for k in data.files}
    except (OSError, KeyError, ValueError):
        return None


def _write(path: Path | None, **arrays) -> None:
    """Arrays into ``path`` (npz), atomically; nothing when it cannot be written."""
    if path is None:
        return
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=path.stem, suffix=".tmp.npz")
        with os.fdopen(fd, "wb") as f:
            np.savez(f, **arrays)
        os.replace(tmp, path)
    except OSError:
        pass


def level_store(mesh: trimesh.Trimesh, faces: int) -> trimesh.Trimesh:
    """``decimate(mesh, faces)``, kept on disk (``levels`` beside the compilation cache,
    ``softshadow.internal.default_cache_dir``; by the mesh's vertices and faces): a new process
    reads the level (a few ms) instead of decimating the mesh again (0.1-0.2 s for the 41k-face
    dragon). A store that cannot be read or written only costs the decimation."""
    if faces >= len(mesh.faces):
        return mesh
    path = _level_path(mesh, faces, "mesh")
    data = _read(path)
    if data is not None:
        return trimesh.Trimesh(np.asarray(data["vertices"], np.float64), np.asarray(data["faces"], np.int64),
                               process=False)
    level = decimate(mesh, faces)
    _write(path, vertices=np.asarray(level.vertices, np.float64), faces=np.asarray(level.faces, np.int32))
    return level


_OCCLUDER_FIELDS = ("vertices", "faces", "face_normals", "edges", "edge_faces", "face_edge_index", "face_edge_dir")


def _stored_occluder(mesh: trimesh.Trimesh, faces: int) -> tuple[int, Occluder]:
    """(the level's face count, its ``Occluder``), kept on disk beside the level (building the
    edge tables of a 20,000-face level takes about 0.1 s)."""
    path = _level_path(mesh, faces, "occluder")
    data = _read(path)
    if data is not None:
        return int(data["mesh_faces"]), Occluder(*(data[k] for k in _OCCLUDER_FIELDS), bool(data["watertight"]))
    level = level_store(mesh, faces)
    occluder = SoftShadowModel.from_mesh(level).occluder
    _write(path, mesh_faces=np.int64(len(level.faces)), watertight=np.bool_(occluder.watertight),
           **{k: getattr(occluder, k) for k in _OCCLUDER_FIELDS})
    return len(level.faces), occluder
