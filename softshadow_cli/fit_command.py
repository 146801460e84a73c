"""``softshadow fit PHOTO_DIR --out OUT_DIR``: fit a photo folder and write its report;
with ``--recursive``, every photo folder under it on Dask (``fitting.fit_many``).

Exit status: 0 when at least one group was fitted; 1 when none was (or the folder cannot be
read); 2 when an option is refused (``validate``), the output place is unusable or holds
results (without ``--force``); 130 on Ctrl-C. Every refusal is one line on stderr
(``--verbose`` adds the details). The table of statuses and messages: docs/formats.md.
"""

from __future__ import annotations

import sys
import tempfile
import time
from pathlib import Path

__all__ = ["run_fit", "run_fit_many", "fit_options", "progress_bar", "check_out_dir"]


def fit_options(args):
    """FitOptions from the fit command's arguments."""
    from fitting import FitOptions
    profiles = ("linear", "disk") if args.profile == "auto" else (args.profile,)
    defaults = FitOptions()
    overlays = getattr(args, "overlays", None) or defaults.overlays
    tolerance = getattr(args, "lod_tolerance", None)
    return FitOptions(profiles=profiles, rule=args.rule, range_k_max=args.range_k_max,
                      plots=args.plots, overlays=overlays, verbose=args.verbose,
                      lod=getattr(args, "lod", "auto"),
                      lod_tolerance=defaults.lod_tolerance if tolerance is None else tolerance)


def progress_bar(total_label: str):
    """A tqdm bar factory over groups, on stderr."""
    from tqdm import tqdm

    def bar(groups):
        return tqdm(total=len(groups), desc=total_label, unit="group", file=sys.stderr)
    return bar


def check_out_dir(out: Path, recursive: bool = False) -> str | None:
    """Why ``out`` cannot take a fit's outputs (one line), or None when it can. Creates nothing:
    the place is probed with a temporary folder in the nearest existing ancestor, removed at once.
    A file where the fit keeps its finished groups (``groups``) is refused; with ``recursive``,
    a folder where the summary goes too."""
    if out.exists() and not out.is_dir():
        return f"--out {out} is a file, not a folder"
    if not recursive and (out / "groups").exists() and not (out / "groups").is_dir():
        return (f"--out {out} holds a file named groups where the finished groups are kept: "
                "move it away or choose another --out")
    if recursive:
        for name in ("summary.csv", "summary.png"):
            if (out / name).is_dir():
                return f"--out {out} holds a folder named {name}, where the summary goes: move it away"
    probe = out
    while not probe.exists():
        if probe.parent == probe:
            break
        probe = probe.parent
    if not probe.is_dir():
        return f"--out {out} cannot be created: {probe} is a file, not a folder"
    try:
        Path(tempfile.mkdtemp(dir=probe, prefix=".softshadow-probe-")).rmdir()
    except OSError as exc:
        return f"--out {out} cannot be written: {probe}: {exc.strerror or exc}"
    return None


def _fail(message: str, code: int) -> int:
    print(f"softshadow fit: {message}", file=sys.stderr)
    return code


def _resume_hint(args) -> str:
    """What to run to resume an interrupted fit: with --force the same command starts over."""
    if args.force:
        return "run the same command without --force to resume (with --force it starts over)"
    return "run the same command again to resume"


def run_fit_many(args) -> int:
    """``softshadow fit ROOT --out OUT --recursive``: every photo folder under ROOT on Dask."""
    from fitting import fit_many
    problem = check_out_dir(Path(args.out), recursive=True)
    if problem:
        return _fail(problem, 2)
    try:
        table = fit_many(args.photo_dir, args.out, scheduler=args.scheduler, workers=args.workers,
                         options=fit_options(args), force=args.force, half_size=args.half_size,
                         jobs=args.jobs)
    except (ValueError, OSError) as exc:
        return _fail(str(exc).splitlines()[0], 1)
    except KeyboardInterrupt:
        from fitting import DONE_MARKER
        done = len(list(Path(args.out).rglob(DONE_MARKER)))
        return _fail(f"interrupted: {done} folder{'s' if done != 1 else ''} done in {args.out}; "
                     + _resume_hint(args), 130)
    failed = table[table["error"].notna()]
    for row in failed.itertuples():
        what = row.folder if not isinstance(row.label, str) else f"{row.folder} group {row.label}"
        print(f"{what}: {row.error}", file=sys.stderr)
    fitted = int(table["rho"].notna().sum())
    folders = table["folder"].nunique()
    print(f"{fitted} group(s) fitted in {folders} folder(s), {len(failed)} failed; "
          f"wrote {Path(args.out) / 'summary.csv'}")
    return 0 if fitted else 1


def run_fit(args) -> int:
    if getattr(args, "recursive", False):
        return run_fit_many(args)
    from fitting import FolderError, fit_and_report, format_table
    out = Path(args.out)
    problem = check_out_dir(out)
    if problem:
        return _fail(problem, 2)
    if (out / "results.json").exists() and not args.force:
        return _fail(f"{out / 'results.json'} exists; use --force to overwrite", 2)
    if args.plots and (out / "plots").exists() and not (out / "plots").is_dir():
        print(f"softshadow fit: no plots: {out / 'plots'} is a file, not a folder (move it away, or "
              "give --no-plots)", file=sys.stderr)
        args.plots = False
    started = time.time()

    def resumed(reused: int, total: int) -> None:
        print(f"softshadow fit: resumed: {reused} of {total} groups reused from {out / 'groups'} (same "
              "photos, scene, options and software); --force refits them", file=sys.stderr)

    try:
        results = fit_and_report(args.photo_dir, out, options=fit_options(args), force=args.force,
                                 half_size=args.half_size, jobs=max(1, args.jobs),
                                 progress=progress_bar("fitting"), on_resume=resumed)
    except FolderError as exc:
        if args.verbose:
            for s in exc.skipped:
                print(f"skipped {s['photo']}: {s['reason']}", file=sys.stderr)
        return _fail(str(exc).splitlines()[0], 1)
    except KeyboardInterrupt:
        kept = len(list((out / "groups").glob("*.json"))) if (out / "groups").is_dir() else 0
        return _fail(f"interrupted: {kept} finished group{'s' if kept != 1 else ''} kept in "
                     f"{out / 'groups'}; " + _resume_hint(args), 130)
    print(format_table(results))
    for g in results.groups:
        if g.error:
            print(f"group {g.label}: {g.error}", file=sys.stderr)
    if results.n_fitted == 0:
        return _fail("no group could be fitted (reasons above)", 1)
    print(_written(out, args.plots, started))
    return 0


def _written(out: Path, wanted: bool, since: float) -> str:
    """The closing line: the files this run wrote, plots counted (PNG) only when some were drawn,
    or why there are none."""
    def fresh(path: Path) -> bool:
        return path.is_file() and path.stat().st_mtime >= since - 1

    files = ", ".join(str(out / n) for n in ("results.json", "table2.md", "index.html") if fresh(out / n))
    if not wanted:
        return f"wrote {files}"
    plots = out / "plots"
    count = sum(1 for f in plots.glob("*.png") if fresh(f)) if plots.is_dir() else 0
    if count:
        return f"wrote {files} and {count} plot{'s' if count != 1 else ''} in {plots}"
    return f"wrote {files} (no plots: no group has a fitted shadow to draw)"
