"""The groups of a folder with geometry, fitted in time order: the mesh and its levels of detail, each
group's views, the resume store, and a pool of threads for ``jobs`` > 1. A failed group never stops
the others."""

from __future__ import annotations

import concurrent.futures
import datetime as _dt
import math
import re
import threading
import time as _time

from scene import SceneError, photo_sun
from softshadow import one_blas_thread

from ..photos.grouping import PhotoGroup, group_photos
from ..photos.views import PhotoView
from ..report.results import GroupResult
from ..verdict.evidence import LevelOfDetail
from .checked import fit_checked
from .read import FolderError
from .resume import group_key, photo_digest
from .views import camera_view, sun_view

__all__ = ["fit_groups", "in_float64"]


def _safe_label(label: str) -> str:
    return re.sub(r"[^A-Za-z0-9_.-]+", "_", label).strip("_") or "group"


def _sun_path(scene, views: list[PhotoView]) -> tuple[float, float] | None:
    """The sun's daily motion at the first photo's time, (d azimuth, d elevation) in degrees per
    minute, when its sun comes from its time and the site; else None."""
    view = views[0]
    if view.sun_source != "time+site" or view.time is None:
        return None
    later = photo_sun(scene, view.name, view.time + _dt.timedelta(minutes=1))
    if later is None:
        return None
    d_az = (later.azimuth_deg - view.sun_azimuth_deg + 180.0) % 360.0 - 180.0
    return float(d_az), float(later.elevation_deg - view.sun_elevation_deg)


def in_float64(fn, *args):
    """fn(*args) in float64 and one BLAS thread: JAX's precision switch is per thread. Fits run
    in float64 (LM in float32 stalls short of its tolerances), scoped to the call so that a
    caller's own JAX code keeps its precision."""
    import jax
    with jax.enable_x64(True), one_blas_thread():
        return fn(*args)


def fit_groups(photos, scene, options, half_size, progress, store, on_group, jobs, times, skipped, software
                ) -> list[GroupResult]:
    """The groups of photos of a scene with geometry, fitted in time order (call it through
    ``in_float64``); photos left out are added to ``skipped``."""
    # Imported here, not at the top: photos without geometry need none of this, and JAX,
    # optimistix and trimesh take seconds to import.
    from softshadow import MeshError, Pose, SunBelowHorizonError, load_mesh
    from ..solve.lod import levels_of_detail
    from ..samples.receiver_points import ReceiverError, load_receiver_mesh, receiver_for_photo

    by_name = {p.name: p for p in photos}
    receiver_meshes: dict = {}
    if scene.receiver.kind == "mesh":
        try:  # one mesh for every photo: a receiver that cannot be read stops the folder
            receiver_meshes["receiver"] = load_receiver_mesh(scene.receiver, scene.base_dir)
        except ReceiverError as exc:
            raise FolderError(str(exc)) from exc
    try:
        mesh = load_mesh(scene.object.mesh, scene.base_dir)
        # The full mesh's model and its levels of detail, built once per mesh and kept between
        # fits (a level is decimated when a group first needs it).
        lods = levels_of_detail(mesh, options.rule)
    except MeshError as exc:
        raise FolderError(f"cannot use the mesh: {exc}") from exc
    model = lods.full
    lod_lock = threading.Lock()
    pose = Pose(scene.object.position, scene.object.rotation_deg, scene.object.scale)
    timed = {n: times[n] for n in times}
    explicit = {n: scene.photo(n).group for n in timed if scene.photo(n).group}
    groups, no_time = group_photos(timed, explicit)
    skipped += [{"photo": n, "reason": r} for n, r in no_time]
    digests = {n: photo_digest(p) for n, p in by_name.items()} if store is not None else {}

    def fit_one(group: PhotoGroup) -> tuple[GroupResult, list[dict]]:
        key = None
        if store is not None:
            key = group_key({n: digests[n] for n in group.photos}, scene, options, software,
                            {"half_size": half_size, "label": group.label})
            kept = store.get(key)
            if kept is not None:
                return kept
        views, group_skipped = [], []
        for name in group.photos:
            photo = by_name[name]
            view = PhotoView(name, photo.gray, photo.excluded, time=times.get(name))
            try:
                camera_view(photo, scene.camera_for(name), view)
                sun_view(name, times.get(name), scene, view)
                view.receiver = receiver_for_photo(scene, name, photo.gray.shape, receiver_meshes)
                if view.receiver.kind != "plane" and view.camera is None:
                    raise ReceiverError(f"a {scene.receiver.kind} receiver needs a perspective camera, "
                                        "not a top-down map")
            except (SunBelowHorizonError, SceneError, ValueError) as exc:
                group_skipped.append({"photo": name, "reason": str(exc).splitlines()[0]})
                continue
            views.append(view)
        if not views:
            result = GroupResult.failed(group.label, group.time, group.photos,
                                        "no usable photo in this group (see skipped)")
        else:
            lod_start = _time.perf_counter()
            try:
                with lod_lock:
                    level = lods.for_group(pose, views, options)
                group_model, sky_model, prepared = level.model, level.sky_model, level.samples
                check = level.check
                detail = LevelOfDetail(level.faces, lods.full_faces, forced=options.lod not in ("auto", "off"),
                                       shift_k_se=check.shift_k_se if check else math.nan,
                                       shift_rho_se=check.shift_rho_se if check else math.nan)
            except Exception as exc:  # a failed choice costs the saving, never the group
                group_model, sky_model, prepared = model, None, None
                note = f"level of detail not chosen ({type(exc).__name__}: {exc}); the full mesh is used"
                detail = LevelOfDetail(lods.full_faces, lods.full_faces, note=note.splitlines()[0])
            lod_seconds = _time.perf_counter() - lod_start
            try:
                result, left_out = fit_checked(group_model, pose, views, group, options, sky_model,
                                               level_of_detail=detail, sun_path=_sun_path(scene, views),
                                               samples=prepared)
                result = result.with_time(lod_seconds)
                group_skipped += left_out
            except Exception as exc:  # a failed group must not lose the others
                result = GroupResult.failed(group.label, group.time, [v.name for v in views],
                                            f"fit failed: {type(exc).__name__}: {exc}".splitlines()[0])
        if store is not None:
            store.put(result, key, group_skipped, _safe_label(group.label))
        return result, group_skipped

    ordered: dict[int, GroupResult] = {}
    bar = progress(groups) if progress else None

    def collect(i: int, result: GroupResult, more: list[dict]) -> None:
        """One finished group: its place in the order, its skipped photos, hook and progress."""
        ordered[i] = result
        skipped.extend(more)
        if on_group:
            on_group(result)
        if bar is not None:
            bar.update(1)

    try:
        if jobs > 1 and len(groups) > 1:
            # Threads: XLA releases the GIL, and the compiled solver is shared between them.
            with concurrent.futures.ThreadPoolExecutor(max_workers=jobs) as pool:
                futures = {pool.submit(in_float64, fit_one, g): i for i, g in enumerate(groups)}
                for future in concurrent.futures.as_completed(futures):
                    collect(futures[future], *future.result())
        else:
            for i, group in enumerate(groups):
                collect(i, *fit_one(group))
    finally:
        if bar is not None:  # also when interrupted: the next line starts on a line of its own
            bar.close()
    return [ordered[i] for i in range(len(groups))]


