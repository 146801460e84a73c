"""``softshadow bench --what startup``: a fit in a fresh process, through the command line and through the
Python API (``fitting.fit_and_report``), alternated, with warm caches (as a user's second run).

Each run is a new Python process that fits the same synthetic folder (the table2 preset at 640x480, three
groups) into a new output folder. The first run of each kind warms the caches and is left out. Reported:
wall and CPU seconds (user + system of the child) per run, their medians, and the ratio API / CLI.
"""

from __future__ import annotations

import os
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

__all__ = ["bench_startup"]

_API = ("import sys; from fitting import fit_and_report; "
        "r = fit_and_report(sys.argv[1], sys.argv[2]); sys.exit(0 if r.n_fitted else 1)")


def _run(cmd: list[str]) -> dict:
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    load = os.getloadavg()[0]
    t0 = time.perf_counter()
    proc = subprocess.run(cmd, capture_output=True, text=True)
    wall = time.perf_counter() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    if proc.returncode != 0:
        raise RuntimeError(f"{' '.join(cmd[:4])} failed: {(proc.stderr or proc.stdout).strip().splitlines()[-1:]}")
    return {"wall_s": round(wall, 2), "cpu_s": round(after.ru_utime + after.ru_stime - before.ru_utime - before.ru_stime, 2),
            "load_before": round(load, 2)}


def bench_startup(quick: bool = False, progress=print) -> dict:
    """Alternated fresh-process fits, ``repeats`` of each kind after one warm-up of each."""
    from data_synth import synthesize

    repeats = 2 if quick else 4
    with tempfile.TemporaryDirectory() as tmp:
        root = Path(tmp)
        progress("bench startup: synthesising the table2 folder (640x480)")
        folder = synthesize(root / "photos", preset="table2", seed=0, size=(640, 480), progress=False)
        kinds = {"cli": lambda out: [sys.executable, "-m", "softshadow", "fit", str(folder), "--out", str(out)],
                 "api": lambda out: [sys.executable, "-c", _API, str(folder), str(out)]}
        runs: dict[str, list[dict]] = {k: [] for k in kinds}
        for i in range(repeats + 1):
            for kind, cmd in kinds.items():
                progress(f"bench startup: {kind} run {i + 1} of {repeats + 1}")
                run = _run(cmd(root / f"{kind}{i}"))
                if i > 0:  # the first of each kind fills the caches
                    runs[kind].append(run)
    out = {kind: {"runs": r, "median_wall_s": round(statistics.median(x["wall_s"] for x in r), 2),
                  "median_cpu_s": round(statistics.median(x["cpu_s"] for x in r), 2)} for kind, r in runs.items()}
    out["api_over_cli_wall"] = round(out["api"]["median_wall_s"] / out["cli"]["median_wall_s"], 2)
    out["api_over_cli_cpu"] = round(out["api"]["median_cpu_s"] / out["cli"]["median_cpu_s"], 2)
    return out
