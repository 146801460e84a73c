"""``softshadow fit`` and ``softshadow demo`` (called by softshadow.cli)."""

from __future__ import annotations

import json
import sys
import time
from pathlib import Path

__all__ = ["run_fit", "run_demo"]


def _options(args):
    from .solve import FitOptions
    profiles = ("linear", "disk") if args.profile == "auto" else (args.profile,)
    return FitOptions(profiles=profiles, rule=args.rule, range_k_max=args.range_k_max,
                      plots=args.plots, overlays=getattr(args, "overlays", "first"),
                      verbose=args.verbose)


def _progress(total_label: str):
    from tqdm import tqdm

    def bar(groups):
        return tqdm(total=len(groups), desc=total_label, unit="group", file=sys.stderr)
    return bar


def fit_and_report(photo_dir, out_dir, options, force=False, half_size=False, truth=None,
                   reference=None, jobs=1):
    """Fit a folder and write results.json, table2.md/.csv and plots; returns FitResults."""
    import concurrent.futures

    from .api import fit_folder
    from .report import plot_group_safely, write_report
    # Each group's plots are drawn in a background thread while the next group is fitted
    # (the fit spends its time in XLA and OpenCV, which release the GIL).
    with concurrent.futures.ThreadPoolExecutor(max_workers=1) as plotter:
        pending = []
        on_group = ((lambda g: pending.append(plotter.submit(plot_group_safely, g, out_dir)))
                    if options.plots else None)
        results = fit_folder(photo_dir, options=options, out_dir=out_dir, force=force,
                             half_size=half_size, progress=_progress("fitting"), jobs=jobs,
                             on_group=on_group)
        group_plots = [p for f in pending for p in f.result()]
    write_report(results, out_dir, reference=reference, truth=truth, plots=options.plots,
                 group_plots=group_plots)
    return results


def run_fit(args) -> int:
    from .api import FolderError
    from .report import format_table
    out = Path(args.out)
    if (out / "results.json").exists() and not args.force:
        print(f"softshadow fit: {out / 'results.json'} exists; use --force to overwrite", file=sys.stderr)
        return 2
    out.mkdir(parents=True, exist_ok=True)
    try:
        results = fit_and_report(args.photo_dir, out, _options(args), force=args.force,
                                 half_size=args.half_size, jobs=max(1, args.jobs))
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


def run_demo(args) -> int:
    from data_synth import synthesize
    from data_synth.cli import parse_size

    from .report import PAPER_TABLE2, format_table
    from .solve import FitOptions
    out = Path(args.out)
    photos = out / "photos"
    t0 = time.perf_counter()
    print("softshadow demo: synthesising the paper's scene (table2 preset: a pillar on white paper, "
          "Iwate, 09:20 / 13:21 / 16:21) with the physical renderer ...", flush=True)
    synthesize(photos, preset="table2", seed=args.seed, renderer="physical", size=parse_size(args.size),
               force=True, progress=True)
    t1 = time.perf_counter()
    truth = json.loads((photos / "truth.json").read_text())
    print(f"  synthesised in {t1 - t0:.1f} s; fitting ...", flush=True)
    results = fit_and_report(photos, out / "fit", FitOptions(), force=True, truth=truth,
                             reference=PAPER_TABLE2)
    t2 = time.perf_counter()
    print(format_table(results, reference=PAPER_TABLE2, truth=truth))
    print(f"fitted in {t2 - t1:.1f} s (compilation included); results in {out / 'fit'}")
    return 0 if results.n_fitted else 1
