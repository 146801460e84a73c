"""Many photo folders at once on Dask: ``fit_many(root, out)`` (``softshadow fit ROOT --recursive``).

Every folder under ``root`` that holds photos is fitted by ``fit_and_report`` into
``out/<its path relative to root>/``; ``out/summary.csv`` has one row per group of every
folder (the documented columns, then ``error``) and ``out/summary.png`` plots k and rho
against time of day, one line per folder.

The work runs on ``dask.distributed``: a ``LocalCluster`` of worker processes with one
thread each (XLA already uses threads inside a fit), or an existing cluster given by its
scheduler address. Workers use JAX's persistent compilation cache (``cache_dir``, by
default ``softshadow.internal.default_cache_dir()``: ``SOFTSHADOW_JAX_CACHE`` or
``~/.cache/softshadow/jax``), so a worker loads the solver another one compiled instead of
compiling it again.

Failures and resuming: a folder that fails (unreadable, no photos, a crash, a lost
worker) gets a row with its reason in ``error`` and never stops the others. A folder that
finished gets a done marker (``out/<folder>/.softshadow-done``) written after its
results.json, carrying the folder's key (``resume.folder_key``: what a single-folder fit
keys its groups with); the next run reuses its results.json while the key matches, and
refits it (reusing its unchanged groups) when anything that decides its results changed.
A folder interrupted half-way keeps its finished groups (``out/<folder>/groups/``) and
fits only the rest; failed folders are tried again.

Ctrl-C: local workers ignore it (a terminal sends it to the whole process group); the
process that started them stops them at once and re-raises it.
"""

from __future__ import annotations

import contextlib
import datetime as _dt
import importlib.util
import json
import os
import signal
import sys
import threading
import time as _time
from pathlib import Path
from collections.abc import Callable

from softshadow import use_compilation_cache

from ..photos.read import list_photos
from ..report.results import FitResults, GroupResult
from ..solve.options import FitOptions

__all__ = ["SUMMARY_COLUMNS", "DONE_MARKER", "find_photo_folders", "fit_many", "folder_rows",
           "write_summary"]

#: summary.csv columns: the documented contract (docs/formats.md), then the reason a folder or group failed.
SUMMARY_COLUMNS = ("folder", "label", "time", "range_k", "range_stderr", "rho", "rho_stderr",
                   "sun_azimuth_deg", "sun_elevation_deg", "reliable", "photos", "error")
#: Written into a folder's output after its results.json: the folder is done (JSON: finished,
#: groups, fitted, seconds spent fitting it).
DONE_MARKER = ".softshadow-done"


def find_photo_folders(root, exclude=None) -> list[Path]:
    """Folders under ``root`` (itself included) that hold at least one photo, sorted.

    Hidden folders and everything under ``exclude`` (the output folder when it lies
    inside ``root``) are not searched.
    """
    root = Path(root)
    skip = Path(exclude).resolve() if exclude is not None else None
    found = []
    for dirpath, dirnames, _ in os.walk(root):
        here = Path(dirpath)
        if skip is not None and (here.resolve() == skip or skip in here.resolve().parents):
            dirnames[:] = []
            continue
        dirnames[:] = sorted(d for d in dirnames if not d.startswith("."))
        if list_photos(here)[0]:
            found.append(here)
    return sorted(found)


def _relative(folder: Path, root: Path) -> str:
    return folder.relative_to(root).as_posix() if folder != root else "."


def folder_rows(folder: str, groups: list[dict]) -> list[dict]:
    """summary.csv rows of one folder from its results.json groups, read back as results
    (``GroupResult.from_json``): a group with an error is never reliable, even in a results.json
    written before that was so."""
    rows = []
    for g in groups:
        data = GroupResult.from_json(g).to_json()
        row = {c: data.get(c) for c in SUMMARY_COLUMNS if c not in ("folder", "photos")}
        row.update(folder=folder, photos=";".join(data["photos"]))
        rows.append(row)
    return rows


def _failure_row(folder: str, reason: str) -> dict:
    """The row of a folder that failed as a whole: a failed group with no label."""
    failed = GroupResult.failed(None, None, (), reason.splitlines()[0] if reason else "failed")
    return folder_rows(folder, [failed.to_json()])[0]


def _done_marker(out_dir: Path) -> dict | None:
    try:
        marker = json.loads((out_dir / DONE_MARKER).read_text())
    except (OSError, ValueError):
        return None
    return marker if isinstance(marker, dict) else None


def _read_done(out_dir: Path, key: str | None) -> list[dict] | None:
    """The groups of a folder already done (its marker and results.json) whose marker carries
    ``key`` (``resume.folder_key``: nothing that decides its results has changed), else None."""
    marker = _done_marker(out_dir)
    if marker is None or key is None or marker.get("key") != key:
        return None
    try:
        return json.loads((out_dir / "results.json").read_text())["groups"]
    except (OSError, ValueError, KeyError, TypeError):
        return None  # a damaged result is simply fitted again


def fit_one_folder(folder, out_dir, options: FitOptions | None = None, force: bool = False,
                   cache_dir=None, half_size: bool = False, jobs: int = 1) -> tuple[list[dict], float]:
    """Fit one folder into ``out_dir`` (``fit_and_report``) and mark it done with its key
    (``resume.folder_key``, taken before the fit reads the folder); the task a Dask worker runs.
    Returns (its results.json groups, seconds spent). Raises what the fit raises (the caller
    records it)."""
    from ..report.files import software_versions
    from .api import fit_and_report
    from .resume import folder_key
    use_compilation_cache(cache_dir)
    start = _time.perf_counter()
    options = options or FitOptions()
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    (out_dir / DONE_MARKER).unlink(missing_ok=True)  # not done while it is being refitted
    key = folder_key(folder, options, software_versions(), half_size)
    results: FitResults = fit_and_report(folder, out_dir, options=options, force=force, half_size=half_size, jobs=jobs)
    seconds = _time.perf_counter() - start
    marker = {"finished": _dt.datetime.now(_dt.UTC).isoformat(timespec="seconds"),
              "groups": len(results.groups), "fitted": results.n_fitted, "seconds": round(seconds, 3),
              "key": key}
    (out_dir / DONE_MARKER).write_text(json.dumps(marker) + "\n")
    return [g.to_json() for g in results.groups], seconds


def _task(folder: str, out_dir: str, options, force: bool, cache_dir, half_size: bool = False,
          jobs: int = 1) -> dict:
    """Worker side: never raises, so one folder's failure is a row, not a lost run."""
    try:
        groups, seconds = fit_one_folder(folder, out_dir, options, force, cache_dir, half_size, jobs)
        return {"groups": groups, "seconds": seconds, "error": None}
    except Exception as exc:  # noqa: BLE001 - any failure of one folder must not stop the others
        from .read import FolderError
        reason = str(exc) if isinstance(exc, FolderError) else f"{type(exc).__name__}: {exc}"
        return {"groups": [], "seconds": 0.0, "error": reason.splitlines()[0] if reason else type(exc).__name__}


def _require_dask() -> None:
    """Dask is an extra (only many folders need it): a one-line ValueError naming it when missing."""
    if importlib.util.find_spec("distributed") is None:
        raise ValueError("many folders (--recursive) run on Dask, which is not installed: "
                         "pip install 'softshadow[many]'")


def _check_scheduler(scheduler: str) -> None:
    if scheduler != "local" and not scheduler.startswith(("tcp://", "tls://", "ws://", "wss://", "ucx://")):
        raise ValueError(f"scheduler must be 'local' or an address such as tcp://HOST:8786, got {scheduler!r}")


_QUIET_TRACKER = "ignore::UserWarning:multiprocessing.resource_tracker"


def _client(scheduler: str, workers: int | None, log: Callable[[str], None]):
    """A dask.distributed Client on a new LocalCluster ("local") or an existing scheduler."""
    from dask.distributed import Client, LocalCluster
    if scheduler == "local":
        n = workers or max(1, os.cpu_count() or 1)
        # A Ctrl-C ends this process at once (the command line's exit), and Python's resource
        # tracker then unlinks the semaphores the cluster's start had made: it starts with this
        # process's warning options, so that it does so without its "leaked semaphore" warning.
        if _QUIET_TRACKER not in sys.warnoptions:
            sys.warnoptions.append(_QUIET_TRACKER)
        # Processes, one thread each: XLA threads inside each fit, and the GIL is not shared.
        with _workers_ignore_ctrl_c(), _ctrl_c_held() as held:
            # A cluster interrupted while it starts cannot be closed (its exit handler then
            # fails with tracebacks): a Ctrl-C waits until it has started, then stops it.
            cluster = LocalCluster(n_workers=n, threads_per_worker=1, processes=True,
                                   dashboard_address=":0", silence_logs=40)
        try:
            if held:
                raise KeyboardInterrupt
            return Client(cluster), cluster
        except KeyboardInterrupt:
            _stop_local(None, cluster)
            raise
    if workers is not None:
        log("--workers is ignored with an existing cluster: it has the workers it has")
    return Client(scheduler, timeout="30s"), None


@contextlib.contextmanager
def _workers_ignore_ctrl_c():
    """Local worker processes started within the block ignore Ctrl-C (SIGINT): a terminal sends
    it to the whole process group, and a worker that took it would print tracebacks (asyncio,
    JAX's exit handler) and keep the cluster from closing; this process stops them instead
    (``_stop_local``). Workers are started through a shell that ignores SIGINT and then runs
    Python, which keeps the signal ignored from its first instruction on; this process's own
    handling of Ctrl-C is not touched, so a Ctrl-C pressed while the cluster starts is not lost."""
    import multiprocessing.spawn as spawn
    import shlex
    import shutil
    import tempfile
    shell = shutil.which("sh") if os.name == "posix" else None
    if shell is None:
        yield
        return
    python = os.fsdecode(spawn.get_executable())
    with tempfile.TemporaryDirectory(prefix="softshadow-worker-") as tmp:
        wrapper = Path(tmp) / "python"
        wrapper.write_text(f"#!{shell}\ntrap '' INT\nexec {shlex.quote(python)} \"$@\"\n")
        wrapper.chmod(0o755)
        if not _runs(wrapper):  # a temporary folder mounted noexec: workers as before
            yield
            return
        spawn.set_executable(str(wrapper))
        try:
            yield
        finally:
            spawn.set_executable(python)


def _runs(wrapper: Path) -> bool:
    import subprocess
    try:
        return subprocess.run([str(wrapper), "-c", "pass"], capture_output=True, timeout=60).returncode == 0
    except (OSError, subprocess.SubprocessError):
        return False


@contextlib.contextmanager
def _ctrl_c_held():
    """Within the block, Ctrl-C is recorded instead of raised (in the main thread, when Python
    handles SIGINT); the list it yields is non-empty when Ctrl-C was pressed."""
    held: list[bool] = []
    previous = signal.getsignal(signal.SIGINT)
    if threading.current_thread() is not threading.main_thread() or not callable(previous):
        yield held
        return
    signal.signal(signal.SIGINT, lambda signum, frame: held.append(True))
    try:
        yield held
    finally:
        signal.signal(signal.SIGINT, previous)


def _stop_local(client, cluster) -> None:
    """Stop a local cluster at once (after a Ctrl-C), without its logs: its workers' fits
    cannot be cut short politely, and waiting for them takes as long as a fit. Kept groups are
    whole files (``resume.GroupStore``), so the next run resumes there."""
    import logging
    quiet = logging.getLogger("distributed")
    level = quiet.level
    quiet.setLevel(logging.CRITICAL)  # "comm closed" and the like: the workers are stopped on purpose
    try:
        for nanny in list(getattr(cluster, "workers", {}).values()):
            pid = getattr(getattr(getattr(nanny, "process", None), "process", None), "pid", None)
            if pid:
                try:
                    os.kill(pid, signal.SIGTERM)
                except OSError:
                    pass
        if client is not None:
            client.close()
        cluster.close()
    finally:
        quiet.setLevel(level)


def _dashboard(client, local: bool) -> str | None:
    """The dashboard link when the scheduler serves one (it needs bokeh, which a local
    scheduler only has when it is installed here)."""
    if local and importlib.util.find_spec("bokeh") is None:
        return None
    try:
        info = client.scheduler_info()
        if "dashboard" not in info.get("services", {}):
            return None
        return client.dashboard_link
    except Exception:  # noqa: BLE001 - a missing dashboard is not an error
        return None


def write_summary(rows: list[dict], out) -> Path:
    """OUT/summary.csv from summary rows (sorted by folder, groups in their order)."""
    import pandas as pd
    table = pd.DataFrame(rows, columns=list(SUMMARY_COLUMNS))
    path = Path(out) / "summary.csv"
    tmp = path.with_suffix(".csv.tmp")
    table.to_csv(tmp, index=False)
    tmp.replace(path)
    return path


def fit_many(root, out, *, scheduler: str = "local", workers: int | None = None,
             options: FitOptions | None = None, force: bool = False, progress: bool = True,
             cache_dir=None, plot: bool = True, log: Callable[[str], None] | None = None,
             half_size: bool = False, jobs: int = 1):
    """Fit every photo folder under ``root`` on Dask; returns the summary (pandas DataFrame,
    columns ``SUMMARY_COLUMNS``, one row per group, or one per failed folder).

    out: each folder goes to ``out/<path relative to root>/``; ``out/summary.csv`` and
    ``out/summary.png`` are written there too.
    scheduler: "local" (a LocalCluster of ``workers`` processes, default one per core) or
    the address of an existing scheduler ("tcp://HOST:8786").
    force: refit folders already done (and their groups). Without it a folder already done
    is reused only while its key matches (``resume.folder_key``: its photos, scene.toml and
    the files it names, the options, ``half_size`` and the software); a changed folder is
    refitted, reusing the groups that did not change.
    half_size, jobs: as ``fit_and_report``'s, for every folder.
    cache_dir: JAX's compilation cache for the workers (default:
    ``softshadow.internal.default_cache_dir()`` as each worker sees it).
    progress: a tqdm bar over folders on stderr; log: where one-line notes go (the
    dashboard address, the folders that changed; default stderr).
    Raises ValueError when ``root`` holds no photo folder, the scheduler is not valid or Dask is not
    installed (the ``many`` extra).
    """
    import pandas as pd
    from tqdm import tqdm

    _require_dask()
    from dask.distributed import as_completed

    from ..report.files import software_versions
    from .resume import folder_key

    log = log or (lambda text: print(text, file=sys.stderr))
    _check_scheduler(scheduler)
    root, out = Path(root), Path(out)
    if not root.is_dir():
        raise ValueError(f"{root} is not a folder")
    folders = find_photo_folders(root, exclude=out)
    if not folders:
        raise ValueError(f"no folder under {root} holds photos")
    out.mkdir(parents=True, exist_ok=True)
    options = options or FitOptions()
    software = software_versions()
    names = [_relative(f, root) for f in folders]
    rows_by: dict[str, list[dict]] = {}
    todo, changed = [], []
    for name, folder in zip(names, folders):
        done = None
        if not force and _done_marker(out / name) is not None:
            done = _read_done(out / name, folder_key(folder, options, software, half_size))
            if done is None:
                changed.append(name)
        if done is not None:
            rows_by[name] = folder_rows(name, done)
        else:
            todo.append((name, folder))
    if changed:
        log(f"{len(changed)} finished folder{'s' if len(changed) != 1 else ''} changed since "
            f"{'its' if len(changed) == 1 else 'their'} results (photos, scene.toml or the files it names, "
            f"options or software), refitted: {', '.join(changed[:5])}{', ...' if len(changed) > 5 else ''}")

    def summary():
        return [r for n in names if n in rows_by for r in rows_by[n]]

    done_count = len(folders) - len(todo)
    if todo:
        client, cluster = _client(scheduler, workers, log)
        bar = None
        try:
            link = _dashboard(client, local=cluster is not None)
            if link:
                log(f"Dask dashboard: {link}")
            futures = {}
            for name, folder in todo:
                fut = client.submit(_task, str(folder), str(out / name), options, force,
                                    None if cache_dir is None else str(cache_dir), half_size, jobs,
                                    key=f"fit-{name}-{_time.time_ns()}", pure=False)
                futures[fut] = name
            bar = tqdm(total=len(folders), initial=done_count, desc="folders", unit="folder",
                       file=sys.stderr, disable=not progress)
            for fut in as_completed(futures):
                name = futures[fut]
                try:
                    result = fut.result()
                except Exception as exc:  # noqa: BLE001 - a lost worker, a cancelled task
                    result = {"groups": [], "error": f"{type(exc).__name__}: {exc}".splitlines()[0]}
                if result["error"] is not None:
                    rows_by[name] = [_failure_row(name, result["error"])]
                else:
                    rows_by[name] = folder_rows(name, result["groups"])
                write_summary(summary(), out)  # an interrupted run keeps what finished
                bar.update(1)
        except KeyboardInterrupt:
            if bar is not None:
                bar.close()
                bar = None
            if cluster is not None:
                _stop_local(client, cluster)
                client = cluster = None
            raise
        finally:
            if bar is not None:
                bar.close()
            if client is not None:
                client.close()
            if cluster is not None:
                cluster.close()
    rows = summary()
    write_summary(rows, out)
    table = pd.DataFrame(rows, columns=list(SUMMARY_COLUMNS))
    if plot:
        from ..report.plots import plot_folders_vs_time
        try:
            plot_folders_vs_time(table, out / "summary.png")
        except Exception as exc:  # noqa: BLE001 - a plot must never cost the numbers
            log(f"summary.png skipped: {type(exc).__name__}: {exc}")
    return table
