"""Fitting photo folders: ``fit_folder`` (files) and ``fit_photos`` (images in memory).

Reads the photos, groups them into times of day, resolves each photo's camera
and sun, fits each group, and returns ``FitResults``. A bad photo or group
never stops the others: each gets a one-line reason in ``skipped`` or in its
group. With ``out_dir`` every finished group is written at once to
``out_dir/groups/``, so an interrupted run loses nothing and resumes there.
"""

from __future__ import annotations

import concurrent.futures
import dataclasses
import datetime as _dt
import json
import re
import threading
import time as _time
from pathlib import Path
from typing import Callable

import cv2
import numpy as np

from scene import CameraSpec, SceneError, SceneSpec, load_scene, photo_sun
from softshadow import one_blas_thread

from .files import software_versions
from .grouping import PhotoGroup, group_photos, photo_time
from .ignore_masks import IgnoreMaskError, ignore_mask_path, read_ignore_mask
from .options import FitOptions
from .photo_check import judge, photo_agreement
from .photos import Photo, PhotoError, list_photos, read_photo
from .resume import GroupStore, group_key, photo_digest
from .results import FitResults, GroupResult
from .uncertainty import edge_rho_errors, profile_spread, range_upper_bound
from .views import PhotoView

__all__ = ["fit_folder", "fit_photos", "fit_and_report", "FolderError", "unreadable_summary"]


class FolderError(ValueError):
    """The folder as a whole cannot be fitted (no images, unreadable scene.toml): a one-line
    reason; ``skipped`` holds the per-file reasons behind it ({"photo", "reason"}), if any."""

    def __init__(self, message: str, skipped: list[dict] | None = None):
        super().__init__(message)
        self.skipped = list(skipped or [])


def unreadable_summary(skipped: list[dict]) -> str:
    """One line for a folder where nothing could be read: how many files and why, by reason
    ("200 files, none readable: 199 text files, 1 empty file"); the details are in ``skipped``."""
    if not skipped:
        return "no image files"
    kinds: dict[tuple[str, str], int] = {}
    for s in skipped:
        kind = _reason_kind(str(s.get("reason", "")))
        kinds[kind] = kinds.get(kind, 0) + 1
    n = len(skipped)
    parts = ", ".join(f"{c} {kind[0] if c == 1 else kind[1]}"
                      for kind, c in sorted(kinds.items(), key=lambda kv: (-kv[1], kv[0])))
    return f"{n} file{'s' if n != 1 else ''}, none readable: {parts}"


# Reasons of fitting.photos, by the words they start with -> the kind of file (singular, plural).
_REASON_KINDS = (("not an image (the file holds text)", "text file", "text files"),
                 ("empty file", "empty file", "empty files"),
                 ("not an image (extension", "file of another type", "files of other types"),
                 ("not an image (no extension", "file without extension", "files without extension"),
                 ("not an image (content", "file that is not an image", "files that are not images"),
                 ("truncated", "truncated image", "truncated images"),
                 ("corrupt", "corrupt image", "corrupt images"),
                 ("unsupported", "unsupported image", "unsupported images"),
                 ("not a RAW", "unreadable RAW file", "unreadable RAW files"))


def _reason_kind(reason: str) -> tuple[str, str]:
    for start, one, many in _REASON_KINDS:
        if reason.startswith(start):
            return one, many
    return "unreadable file", "unreadable files"


def _safe_label(label: str) -> str:
    return re.sub(r"[^A-Za-z0-9_.-]+", "_", label).strip("_") or "group"


def _camera_view(photo: Photo, spec: CameraSpec | None, view: PhotoView) -> None:
    """Fill the view's camera or grid from the scene; markers are registered here."""
    h, w = photo.gray.shape
    if spec is None:
        raise ValueError("no camera: give [camera] (explicit, topdown or markers) in scene.toml")
    if spec.kind == "topdown":
        view.grid = spec.grid(w, h)
    elif spec.kind == "explicit":
        cam = spec.pinhole(w, h)
        view.camera = cam
    else:
        from .markers import board_outline_world, register_board
        # Intrinsics: scene.toml's K with its distortion, else EXIF, else fitted (register_board).
        reg = register_board(photo.gray, spec, exif=photo.exif)
        view.camera = reg.camera
        view.reprojection_error_px = reg.reprojection_error_px
        outline = board_outline_world(spec)
        uv, front = reg.camera.project(outline)
        ignore = np.zeros((h, w), np.uint8)
        if front.all():
            cv2.fillConvexPoly(ignore, np.rint(uv).astype(np.int32), 1)
            ignore = cv2.dilate(ignore, np.ones((9, 9), np.uint8))
        view.ignore = ignore.astype(bool)


def _sun_view(name: str, when: _dt.datetime | None, scene: SceneSpec, view: PhotoView) -> None:
    from softshadow import check_sun_above_horizon  # with JAX (see _fit_groups)
    sun = photo_sun(scene, name, when)
    if sun is None:
        view.sun_source = "fitted"
        return
    view.sun_azimuth_deg, view.sun_elevation_deg, view.sun_source = sun.azimuth_deg, sun.elevation_deg, sun.source
    check_sun_above_horizon(view.sun_elevation_deg)


def _fit_group_with_sun(model, pose, views, group: PhotoGroup, options: FitOptions, sky_model=None) -> GroupResult:
    """Fit a group; when the sun is unknown, search for it coarsely, then fit and re-plan."""
    from .solve import fit_group  # with JAX (see _fit_groups)
    if all(v.sun_source != "fitted" for v in views):
        return fit_group(model, pose, views, group.label, group.time, options, sky_model)
    from .sun_search import search_sun
    az, el, _ = search_sun(model, pose, views[0])
    for v in views:
        v.sun_azimuth_deg, v.sun_elevation_deg = az, el
    result = None
    for _ in range(3):  # re-plan around the refined sun
        result = fit_group(model, pose, views, group.label, group.time, options, sky_model)
        if not result.fitted:
            return result
        moved = abs(result.sun_azimuth_deg - views[0].sun_azimuth_deg) + abs(
            result.sun_elevation_deg - views[0].sun_elevation_deg)
        for v in views:
            v.sun_azimuth_deg, v.sun_elevation_deg = result.sun_azimuth_deg, result.sun_elevation_deg
        if moved < 0.05:
            break
    return result


def _measure_without_scene(photo: Photo, when, scene: SceneSpec | None) -> GroupResult:
    from .edge_measure import measure_shadow_edges
    start = _time.perf_counter()
    label = photo.name
    time_label = when.strftime("%H:%M") if when is not None else None
    result = GroupResult(label=label, time=time_label, photos=[photo.name])
    pixel_m = None
    if scene is not None and scene.camera is not None and scene.camera.kind == "topdown":
        pixel_m = scene.camera.pixel_m
    m = measure_shadow_edges(photo.gray, mask=photo.excluded, pixel_m=pixel_m, linear_rgb=photo.linear)
    result.seconds = _time.perf_counter() - start
    if not m.edges_found:
        result.error = m.reason or "no shadow edge found"
        return result
    kept_log_rho = np.log([p.rho for p in m.profiles if p.kept])
    errors = edge_rho_errors(m.rho, m.rho_stderr, profile_spread(kept_log_rho))
    result.rho, result.rho_stderr = float(m.rho), errors.rho_stderr
    result.rho_stderr_stat, result.rho_stderr_sys = errors.rho_stderr_stat, errors.rho_stderr_sys
    result.penumbra_px, result.penumbra_px_iqr = float(m.penumbra_px), float(m.penumbra_px_iqr)
    result.penumbra_m = None if m.penumbra_m is None else float(m.penumbra_m)
    result.n_profiles = int(m.n_profiles)
    result.converged = True
    result.identifiable = True
    result.warnings, result.reliable = list(m.warnings), bool(m.reliable)
    return result


def _fit_checked(model, pose, views: list[PhotoView], group: PhotoGroup,
                 options: FitOptions, sky_model=None) -> tuple[GroupResult, list[dict]]:
    """Fit a group, then check each photo against the fit (``photo_check``): a photo that does not
    fit is left out (a ``skipped`` entry naming the group and why) and the group refitted without
    it; a group where no photo shows a shadow gets "no shadow in view" and no values; a doubt that
    cannot be resolved makes the group unreliable, with a warning."""
    start = _time.perf_counter()
    # The check reads the fit's profile data, which the fit builds only when plots are wanted; it
    # does not read the overlays, which are drawn only when plots are (0.4-0.5 s a group).
    checked = dataclasses.replace(options, plots=True, overlays=options.overlays if options.plots else "none")
    left_out: list[dict] = []
    while True:
        result = _fit_group_with_sun(model, pose, views, PhotoGroup(group.label, group.time,
                                                                    [v.name for v in views]), checked, sky_model)
        if not result.fitted:
            break
        verdict = judge(photo_agreement(result))
        if verdict.no_shadow:
            result = GroupResult(group.label, group.time, [v.name for v in views], error=verdict.no_shadow,
                                 warnings=result.warnings)
            break
        if verdict.leave_out and len(views) > 1:
            name, reason = verdict.leave_out[0]
            left_out.append({"photo": name, "reason": f"left out of group {group.label}: {reason}"})
            views = [v for v in views if v.name != name]
            continue
        if verdict.warnings:
            result.warnings += verdict.warnings
            result.reliable = False
        if verdict.range_unmeasured and result.identifiable and result.range_k is not None:
            # What hides the rho measurement hides the penumbra's width too: k is then a bound.
            result.identifiable = False
            result.range_k = range_upper_bound(result.range_k, result.range_stderr_stat or 0.0, result.penumbra_px,
                                               result.range_stderr)
            result.warnings.append(f"range not identifiable: {verdict.range_unmeasured}; range_k is an upper bound")
        break
    if result.fitted and result.identifiable and result.range_k is not None and result.range_k > options.range_k_max:
        # The samples' band and the start were sized for k up to range_k_max: beyond it the band
        # may cut the penumbra short.
        result.warnings.append(f"k = {result.range_k:.4g} is beyond range_k_max = {options.range_k_max:g}: the "
                               "samples may not cover the whole penumbra (raise --range-k-max)")
        result.reliable = False
    if left_out and result.fitted:
        result.warnings.append("refitted without " + ", ".join(s["photo"] for s in left_out)
                               + ", which did not fit the other photos (see skipped)")
    if not options.plots:
        result.plot_profiles, result.plot_overlays = [], []
    result.seconds = _time.perf_counter() - start
    return result, left_out


def fit_photos(photos: list[Photo], scene: SceneSpec | None = None, options: FitOptions | None = None,
               half_size: bool = False, progress: Callable | None = None,
               store: GroupStore | None = None,
               on_group: Callable[[GroupResult], None] | None = None, jobs: int = 1) -> FitResults:
    """Fit photos already decoded (``fitting.photos.read_photo``) with an optional scene.

    store: finished groups kept on disk (``fitting.resume.GroupStore``): a group whose resume key
    (photos' contents, scene, options, software) matches a record is reused, and every group
    fitted is written there as soon as it is finished.
    on_group: called with each group's result as soon as it is finished.
    progress: a callable returning a progress bar (tqdm-like: update, close) for the groups.
    jobs: groups fitted at once (threads).
    """
    # One BLAS thread (softshadow.one_blas_thread); fits with geometry run in float64 (_in_float64).
    with one_blas_thread():
        return _fit_photos(photos, scene, options or FitOptions(), half_size, progress, store, on_group,
                           jobs)


def _in_float64(fn, *args):
    """fn(*args) in float64 and one BLAS thread: JAX's precision switch is per thread. Fits run
    in float64 (LM in float32 stalls short of its tolerances), scoped to the call so that a
    caller's own JAX code keeps its precision."""
    import jax
    with jax.enable_x64(True), one_blas_thread():
        return fn(*args)


def _fit_photos(photos, scene, options, half_size, progress, store, on_group, jobs) -> FitResults:
    skipped: list[dict] = []
    software = software_versions()
    times = {}
    for p in photos:
        try:
            times[p.name] = photo_time(p.name, p.exif, scene)
        except SceneError as exc:
            # One entry per photo: the unreadable time, not also "no time" from the grouping.
            skipped.append({"photo": p.name, "reason": str(exc)})
    if scene is None or scene.object is None:
        # No geometry: each photo on its own (CONVENTIONS).
        groups_out: list[GroupResult] = []
        for p in photos:
            result = _measure_without_scene(p, times.get(p.name), scene)
            groups_out.append(result)
            if on_group:
                on_group(result)
        return FitResults(groups_out, skipped, software)
    groups_out = _in_float64(_fit_groups, photos, scene, options, half_size, progress, store, on_group, jobs,
                             times, skipped, software)
    return FitResults(groups_out, skipped, software)


def _fit_groups(photos, scene, options, half_size, progress, store, on_group, jobs, times, skipped, software
                ) -> list[GroupResult]:
    """The groups of photos of a scene with geometry, fitted in time order (call it through
    ``_in_float64``); photos left out are added to ``skipped``."""
    # Imported here, not at the top: photos without geometry need none of this, and JAX,
    # optimistix and trimesh take seconds to import.
    from softshadow import MeshError, Pose, SunBelowHorizonError, load_mesh
    from .lod import levels_of_detail
    from .receiver_points import ReceiverError, load_receiver_mesh, receiver_for_photo

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
                _camera_view(photo, scene.camera_for(name), view)
                _sun_view(name, times.get(name), scene, view)
                view.receiver = receiver_for_photo(scene, name, photo.gray.shape, receiver_meshes)
                if view.receiver.kind != "plane" and view.camera is None:
                    raise ReceiverError(f"a {scene.receiver.kind} receiver needs a perspective camera, "
                                        "not a top-down map")
            except (SunBelowHorizonError, SceneError, ValueError) as exc:
                group_skipped.append({"photo": name, "reason": str(exc).splitlines()[0]})
                continue
            views.append(view)
        if not views:
            result = GroupResult(group.label, group.time, group.photos,
                                 error="no usable photo in this group (see skipped)")
        else:
            lod_start = _time.perf_counter()
            try:
                with lod_lock:
                    group_model, faces = lods.for_group(pose, views, options)
                    sky_model = lods.sky_level(faces) if options.lod == "auto" else None
                lod_note = None
            except Exception as exc:  # a failed choice costs the saving, never the group
                group_model, faces, sky_model = model, lods.full_faces, None
                lod_note = f"level of detail not chosen ({type(exc).__name__}: {exc}); the full mesh is used"
            lod_seconds = _time.perf_counter() - lod_start
            try:
                result, left_out = _fit_checked(group_model, pose, views, group, options, sky_model)
                result.seconds += lod_seconds
                result.lod_faces, result.mesh_faces = faces, lods.full_faces
                if lod_note:
                    result.warnings.append(lod_note.splitlines()[0])
                group_skipped += left_out
            except Exception as exc:  # a failed group must not lose the others
                result = GroupResult(group.label, group.time, [v.name for v in views],
                                     error=f"fit failed: {type(exc).__name__}: {exc}".splitlines()[0])
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
                futures = {pool.submit(_in_float64, fit_one, g): i for i, g in enumerate(groups)}
                for future in concurrent.futures.as_completed(futures):
                    collect(futures[future], *future.result())
        else:
            for i, group in enumerate(groups):
                collect(i, *fit_one(group))
    finally:
        if bar is not None:  # also when interrupted: the next line starts on a line of its own
            bar.close()
    return [ordered[i] for i in range(len(groups))]


def fit_folder(path, scene: SceneSpec | str | Path | None = None, options: FitOptions | None = None,
               out_dir=None, force: bool = False, half_size: bool = False,
               progress: Callable | None = None, jobs: int = 1,
               on_group: Callable[[GroupResult], None] | None = None,
               on_resume: Callable[[int, int], None] | None = None) -> FitResults:
    """Fit every time of day in a photo folder.

    scene: a SceneSpec, a path to a scene.toml, or None to read ``path/scene.toml`` if any.
    out_dir: when given, finished groups are kept in ``out_dir/groups/*.json`` as they
    finish and reused on the next run when nothing that decides them changed (``fitting.resume``);
    ``force`` removes the kept groups and a previous report first, then refits everything.
    on_group: called with each group's result as soon as it is finished (and kept).
    on_resume: called once with (groups reused, groups in all) when kept groups were reused.
    Raises FolderError when nothing in the folder can be read.
    """
    folder = Path(path)
    if not folder.is_dir():
        raise FolderError(f"{folder} is not a folder")
    if scene is None and (folder / "scene.toml").exists():
        scene = folder / "scene.toml"
    if isinstance(scene, (str, Path)):
        try:
            scene = load_scene(scene)
        except SceneError as exc:
            raise FolderError(str(exc)) from exc
    files, skipped_files = list_photos(folder)
    skipped = [{"photo": n, "reason": r} for n, r in skipped_files]
    photos = []
    for f in files:
        try:
            photo = read_photo(f, half_size=half_size)
            mask_path = ignore_mask_path(f, scene)
            if mask_path is not None:
                photo.ignore = read_ignore_mask(mask_path, photo.gray.shape)
            photos.append(photo)
        except PhotoError as exc:
            skipped.append({"photo": f.name, "reason": exc.reason})
        except IgnoreMaskError as exc:
            skipped.append({"photo": f.name, "reason": str(exc)})
    if not photos:
        raise FolderError(f"no readable photo in {folder}: {unreadable_summary(skipped)}", skipped)
    store = None
    if out_dir is not None:
        from .report import clear_report
        store = GroupStore(Path(out_dir) / "groups", force=force)
        if force:
            # Old groups and the old report go before the first new group is kept: a refit
            # stopped half-way leaves only the new groups, which the next run resumes.
            store.clear()
            clear_report(out_dir)
    results = fit_photos(photos, scene, options, half_size, progress, store, on_group, jobs)
    if store is not None and store.reused and on_resume is not None:
        on_resume(store.reused, len(results.groups))
    results.skipped = skipped + results.skipped
    return results


def fit_and_report(photo_dir, out_dir, options: FitOptions | None = None, force: bool = False,
                   half_size: bool = False, truth=None, reference=None, jobs: int = 1,
                   progress: Callable | None = None,
                   on_resume: Callable[[int, int], None] | None = None) -> FitResults:
    """Fit a folder and write everything into ``out_dir``: results.json, table2.md/.csv and
    plots/ (``fit_folder`` then ``report.write_report``); returns the FitResults.

    truth, reference: a truth.json document and the paper's table, shown beside the fit.
    on_resume: see ``fit_folder``.
    """
    from .report import plot_group_safely, write_report

    options = options or FitOptions()
    # Each group's plots are drawn in a background thread while the next group is fitted
    # (the fit spends its time in XLA and OpenCV, which release the GIL).
    with concurrent.futures.ThreadPoolExecutor(max_workers=1) as plotter:
        pending = []
        on_group = ((lambda g: pending.append(plotter.submit(plot_group_safely, g, out_dir)))
                    if options.plots else None)
        results = fit_folder(photo_dir, options=options, out_dir=out_dir, force=force,
                             half_size=half_size, progress=progress, jobs=jobs,
                             on_group=on_group, on_resume=on_resume)
        group_plots = [p for f in pending for p in f.result()]
    write_report(results, out_dir, reference=reference, truth=truth, plots=options.plots,
                 group_plots=group_plots)
    return results
