"""``softshadow fit PHOTO_DIR --out OUT_DIR``: fit a photo folder and write its report;
with ``--recursive``, every photo folder under it on Dask (``fitting.fit_many``).

Exit status: 0 when at least one group was fitted; 1 when none was (or the folder cannot be
read); 2 when the output place is unusable or holds results (without ``--force``); 130 on
Ctrl-C. Every refusal is one line on stderr (``--verbose`` adds the details).
"""

from __future__ import annotations

import sys
import tempfile
from pathlib import Path

__all__ = ["run_fit", "run_fit_many", "fit_options", "progress_bar", "check_out_dir"]


def fit_options(args):
    """FitOptions from the fit command's arguments."""
    from fitting import FitOptions
    profiles = ("linear", "disk") if args.profile == "auto" else (args.profile,)
    return FitOptions(profiles=profiles, rule=args.rule, range_k_max=args.range_k_max,
                      plots=args.plots, overlays=getattr(args, "overlays", "first"),
                      verbose=args.verbose, lod=getattr(args, "lod", "auto"),
                      lod_tolerance=getattr(args, "lod_tolerance", 0.1))


def progress_bar(total_label: str):
    """A tqdm bar factory over groups, on stderr."""
    from tqdm import tqdm

    def bar(groups):
        return tqdm(total=len(groups), desc=total_label, unit="group", file=sys.stderr)
    return bar


def check_out_dir(out: Path) -> str | None:
    """Why ``out`` cannot take a fit's outputs (one line), or None when it can. Creates nothing:
    the place is probed with a temporary folder in the nearest existing ancestor, removed at once."""
    if out.exists() and not out.is_dir():
        return f"--out {out} is a file, not a folder"
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


def run_fit_many(args) -> int:
    """``softshadow fit ROOT --out OUT --recursive``: every photo folder under ROOT on Dask."""
    from fitting import fit_many
    if args.workers is not None and args.workers < 1:
        return _fail(f"--workers must be at least 1, got {args.workers}", 2)
    problem = check_out_dir(Path(args.out))
    if problem:
        return _fail(problem, 2)
    try:
        table = fit_many(args.photo_dir, args.out, scheduler=args.scheduler, workers=args.workers,
                         options=fit_options(args), force=args.force)
    except (ValueError, OSError) as exc:
        return _fail(str(exc).splitlines()[0], 1)
    except KeyboardInterrupt:
        from fitting import DONE_MARKER
        done = len(list(Path(args.out).rglob(DONE_MARKER)))
        return _fail(f"interrupted: {done} folder{'s' if done != 1 else ''} done in {args.out}; run the "
                     "same command again to resume", 130)
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
    if getattr(args, "scheduler", "local") != "local" or getattr(args, "workers", None) is not None:
        return _fail("--scheduler and --workers go with --recursive", 2)
    from fitting import FolderError, fit_and_report, format_table
    out = Path(args.out)
    problem = check_out_dir(out)
    if problem:
        return _fail(problem, 2)
    if (out / "results.json").exists() and not args.force:
        return _fail(f"{out / 'results.json'} exists; use --force to overwrite", 2)

    def resumed(reused: int, total: int) -> None:
        print(f"softshadow fit: resumed: {reused} of {total} groups reused from {out / 'groups'} (same "
              "photos, scene, options and software); --force refits them", file=sys.stderr)

    try:
        results = fit_and_report(args.photo_dir, out, fit_options(args), force=args.force,
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
                     f"{out / 'groups'}; run the same command again to resume", 130)
    print(format_table(results))
    for g in results.groups:
        if g.error:
            print(f"group {g.label}: {g.error}", file=sys.stderr)
    if results.n_fitted == 0:
        return _fail("no group could be fitted (reasons above)", 1)
    print(f"wrote {out / 'results.json'}, {out / 'table2.md'}" + (f", {out / 'plots'}" if args.plots else ""))
    return 0
