"""``softshadow demo``: synthesise the paper's scene, fit it, print the table beside the truth."""

from __future__ import annotations

import json
import time
from pathlib import Path

__all__ = ["run_demo"]


def run_demo(args) -> int:
    from data_synth import synthesize
    from fitting import PAPER_TABLE2, FitOptions, fit_and_report, format_table

    from .fit_command import progress_bar
    from .synth_command import parse_size
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
                             reference=PAPER_TABLE2, progress=progress_bar("fitting"))
    t2 = time.perf_counter()
    print(format_table(results, reference=PAPER_TABLE2, truth=truth))
    print(f"fitted in {t2 - t1:.1f} s (compilation included); results in {out / 'fit'}")
    return 0 if results.n_fitted else 1
