"""``softshadow fit PHOTO_DIR --out OUT_DIR``: fit a photo folder and write its report;
with ``--recursive``, every photo folder under it on Dask (``fitting.fit_many``)."""

from __future__ import annotations

import sys
from pathlib import Path

__all__ = ["run_fit", "run_fit_many", "fit_options", "progress_bar"]


def fit_options(args):
    """FitOptions from the fit command's arguments."""
    from fitting import FitOptions
    profiles = ("linear", "disk") if args.profile == "auto" else (args.profile,)
    return FitOptions(profiles=profiles, rule=args.rule, range_k_max=args.range_k_max,
                      plots=args.plots, overlays=getattr(args, "overlays", "first"),
                      verbose=args.verbose)


def progress_bar(total_label: str):
    """A tqdm bar factory over groups, on stderr."""
    from tqdm import tqdm

    def bar(groups):
        return tqdm(total=len(groups), desc=total_label, unit="group", file=sys.stderr)
    return bar


def run_fit_many(args) -> int:
    """``softshadow fit ROOT --out OUT --recursive``: every photo folder under ROOT on Dask."""
    from fitting import fit_many
    if args.workers is not None and args.workers < 1:
        print(f"softshadow fit: --workers must be at least 1, got {args.workers}", file=sys.stderr)
        return 2
    try:
        table = fit_many(args.photo_dir, args.out, scheduler=args.scheduler, workers=args.workers,
                         options=fit_options(args), force=args.force)
    except (ValueError, OSError) as exc:
        print(f"softshadow fit: {str(exc).splitlines()[0]}", file=sys.stderr)
        return 1
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
        print("softshadow fit: --scheduler and --workers go with --recursive", file=sys.stderr)
        return 2
    from fitting import FolderError, fit_and_report, format_table
    out = Path(args.out)
    if (out / "results.json").exists() and not args.force:
        print(f"softshadow fit: {out / 'results.json'} exists; use --force to overwrite", file=sys.stderr)
        return 2
    out.mkdir(parents=True, exist_ok=True)
    try:
        results = fit_and_report(args.photo_dir, out, fit_options(args), force=args.force,
                                 half_size=args.half_size, jobs=max(1, args.jobs),
                                 progress=progress_bar("fitting"))
    except FolderError as exc:
        print(f"softshadow fit: {exc}", file=sys.stderr)
        return 1
    print(format_table(results))
    for g in results.groups:
        if g.error:
            print(f"group {g.label}: {g.error}", file=sys.stderr)
    if results.n_fitted == 0:
        print("softshadow fit: no group could be fitted (reasons above)", file=sys.stderr)
        return 1
    print(f"wrote {out / 'results.json'}, {out / 'table2.md'}, {out / 'plots'}")
    return 0
