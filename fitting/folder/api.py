"""Fitting photo folders: ``fit_folder`` (files), ``fit_photos`` (images in memory) and ``fit_and_report``.

Reads the photos, groups them into times of day, resolves each photo's camera
and sun, fits each group, and returns ``FitResults``. A bad photo or group
never stops the others: each gets a one-line reason in ``skipped`` or in its
group. With ``out_dir`` every finished group is written at once to
``out_dir/groups/``, so an interrupted run loses nothing and resumes there.
"""

from __future__ import annotations

import concurrent.futures
from pathlib import Path
from collections.abc import Callable

from scene import SceneError, SceneSpec, load_scene
from softshadow import one_blas_thread, use_compilation_cache

from ..photos.grouping import photo_time
from ..photos.read import Photo
from ..report.files import software_versions
from ..report.results import FitResults, GroupResult
from ..solve.options import FitOptions
from .groups import fit_groups, in_float64
from .no_geometry import measure_without_scene
from .read import FolderError, read_folder
from .resume import GroupStore

__all__ = ["fit_folder", "fit_photos", "fit_and_report", "FolderError"]


def fit_photos(photos: list[Photo], scene: SceneSpec | None = None, *, options: FitOptions | None = None,
               half_size: bool = False, progress: Callable | None = None,
               store: GroupStore | None = None,
               on_group: Callable[[GroupResult], None] | None = None, jobs: int = 1) -> FitResults:
    """Fit photos already decoded (``fitting.photos.read.read_photo``) with an optional scene.

    store: finished groups kept on disk (``fitting.folder.resume.GroupStore``): a group whose resume key
    (photos' contents, scene, options, software) matches a record is reused, and every group
    fitted is written there as soon as it is finished.
    on_group: called with each group's result as soon as it is finished.
    progress: a callable returning a progress bar (tqdm-like: update, close) for the groups.
    jobs: groups fitted at once (threads).

    Like the command line, it keeps compiled and traced programs between processes
    (``softshadow.use_compilation_cache``: ``~/.cache/softshadow/jax``, or ``SOFTSHADOW_JAX_CACHE``;
    ``SOFTSHADOW_JAX_CACHE=off`` leaves them off), so a new process fits as fast as ``softshadow fit``.
    """
    # The caches that let a new process skip tracing and compiling the solver, as the command line has.
    use_compilation_cache()
    # One BLAS thread (softshadow.one_blas_thread); fits with geometry run in float64 (``groups.in_float64``).
    with one_blas_thread():
        return _fit_photos(photos, scene, options or FitOptions(), half_size, progress, store, on_group,
                           jobs)


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
        # No geometry: each photo on its own (docs/formats.md).
        groups_out: list[GroupResult] = []
        for p in photos:
            result = measure_without_scene(p, times.get(p.name), scene)
            groups_out.append(result)
            if on_group:
                on_group(result)
        return FitResults(groups_out, skipped, software)
    groups_out = in_float64(fit_groups, photos, scene, options, half_size, progress, store, on_group, jobs,
                             times, skipped, software)
    return FitResults(groups_out, skipped, software)


def fit_folder(path, scene: SceneSpec | str | Path | None = None, *, options: FitOptions | None = None,
               out_dir=None, force: bool = False, half_size: bool = False,
               progress: Callable | None = None, jobs: int = 1,
               on_group: Callable[[GroupResult], None] | None = None,
               on_resume: Callable[[int, int], None] | None = None) -> FitResults:
    """Fit every time of day in a photo folder.

    scene: a SceneSpec, a path to a scene.toml, or None to read ``path/scene.toml`` if any.
    out_dir: when given, finished groups are kept in ``out_dir/groups/*.json`` as they
    finish and reused on the next run when nothing that decides them changed (``fitting.folder.resume``);
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
    photos, skipped = read_folder(folder, scene, half_size)
    store = None
    if out_dir is not None:
        from ..report.write import clear_report
        store = GroupStore(Path(out_dir) / "groups", force=force)
        if force:
            # Old groups and the old report go before the first new group is kept: a refit
            # stopped half-way leaves only the new groups, which the next run resumes.
            store.clear()
            clear_report(out_dir)
    results = fit_photos(photos, scene, options=options, half_size=half_size, progress=progress, store=store,
                         on_group=on_group, jobs=jobs)
    if store is not None and store.reused and on_resume is not None:
        on_resume(store.reused, len(results.groups))
    results.skipped = skipped + results.skipped
    return results


def fit_and_report(photo_dir, out_dir, *, options: FitOptions | None = None, force: bool = False,
                   half_size: bool = False, truth=None, reference=None, jobs: int = 1,
                   progress: Callable | None = None,
                   on_resume: Callable[[int, int], None] | None = None) -> FitResults:
    """Fit a folder and write everything into ``out_dir``: results.json, table2.md/.csv and
    plots/ (``fit_folder`` then ``report.write_report``); returns the FitResults.

    truth, reference: a truth.json document and the paper's table, shown beside the fit.
    on_resume: see ``fit_folder``.
    """
    from ..report.write import plot_group_safely, write_report

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
