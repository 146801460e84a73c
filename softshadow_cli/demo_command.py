"""``softshadow demo``: synthesise the paper's scene, fit it, print the table beside the truth and a verdict."""

from __future__ import annotations

import json
import time
from pathlib import Path

__all__ = ["run_demo", "demo_verdict"]


def demo_verdict(results, truth) -> str:
    """One line: in how many groups k and rho lie within two stated errors of the truth, naming each miss
    in stated errors (an upper bound on k counts as right when the truth lies under it)."""
    from fitting.report.comparison import truth_for_group

    misses, n = [], 0
    for g in results.groups:
        t = truth_for_group(g, truth)
        if t is None:
            continue
        n += 1
        if not g.fitted:
            misses.append(f"{g.label}: not fitted ({g.error})")
            continue
        off = []
        if g.range_k is not None and t.get("range_k") is not None:
            if not g.identifiable:
                if t["range_k"] > g.range_k:
                    off.append(f"k's bound {g.range_k:.3g} under the truth {t['range_k']:.3g}")
            elif g.range_stderr and abs(g.range_k - t["range_k"]) > 2 * g.range_stderr:
                off.append(f"k {abs(g.range_k - t['range_k']) / g.range_stderr:.1f} stated errors off")
        if g.rho is not None and t.get("rho") is not None and g.rho_stderr:
            if abs(g.rho - t["rho"]) > 2 * g.rho_stderr:
                off.append(f"ρ {abs(g.rho - t['rho']) / g.rho_stderr:.1f} stated errors off")
        if off:
            misses.append(f"{g.label}: " + ", ".join(off))
    right = n - len(misses)
    head = f"verdict: k and ρ within two stated errors of the truth in {right} of {n} groups"
    return head + (" (" + "; ".join(misses) + ")" if misses else "")


def run_demo(args) -> int:
    from data_synth import synthesize
    from fitting import PAPER_TABLE2, FitOptions, fit_and_report, format_table

    from .fit_command import progress_bar
    from .synth_command import parse_size
    out = Path(args.out)
    photos = out / "photos"
    t0 = time.perf_counter()
    print(f"softshadow demo: synthesising the paper's scene into {photos.resolve()} (a pillar on white paper, "
          "Iwate, at the paper's three times of day) with the physical renderer ...", flush=True)
    synthesize(photos, preset="table2", seed=args.seed, renderer="physical", size=parse_size(args.size),
               force=True, progress=True)
    t1 = time.perf_counter()
    truth = json.loads((photos / "truth.json").read_text())
    print(f"  synthesised in {t1 - t0:.1f} s; fitting ...", flush=True)
    results = fit_and_report(photos, out / "fit", options=FitOptions(), force=True, truth=truth,
                             reference=PAPER_TABLE2, progress=progress_bar("fitting"))
    t2 = time.perf_counter()
    print(format_table(results, reference=PAPER_TABLE2, truth=truth))
    print(demo_verdict(results, truth))
    fit_dir = (out / "fit").resolve()
    print(f"fitted in {t2 - t1:.1f} s (compilation included). Photos in {photos.resolve()}; results in "
          f"{fit_dir} (open {fit_dir / 'index.html'}).")
    return 0 if results.n_fitted else 1
