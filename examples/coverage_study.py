"""The calibration study's coverage under another systematic floor, and the floor that reaches a target.

Usage:
    python examples/coverage_study.py STUDY.json [--floor K_REL K_REL_PX RHO_ABS RHO_REL]
        [--calibrate] [--target 0.9] [--all-groups] [--well-described]

STUDY.json is the JSON of ``softshadow bench --what coverage`` (docs/uncertainty_study.json) or a
records.jsonl of a running study. The floor (``fitting.solve.uncertainty.SystematicFloor``) does not
change a fit's values, only its stated errors: each stated error is recomputed from the record's
statistical part and the floor's systematic part, so a floor is tried on every group without
refitting. Coverage counts the groups reported reliable (``--all-groups``: every fitted group), as in
the study's tables (``benchmarks.coverage_tables``). ``--calibrate`` searches a grid for the floor with
the smallest mean log stated error that covers at least ``--target`` of k and of rho within 2 sigma.
"""

from __future__ import annotations

import argparse
import itertools
import json
import sys
from pathlib import Path

import numpy as np

from fitting.solve.uncertainty import CALIBRATED_FLOOR, SystematicFloor, systematic_errors


def read_records(path: Path) -> list[dict]:
    text = Path(path).read_text()
    if path.suffix == ".jsonl":
        return [json.loads(line) for line in text.splitlines() if line.strip()]
    return json.loads(text)["records"]


def usable(records: list[dict], all_groups: bool, well_described: bool = False) -> list[dict]:
    """Fitted groups with their statistical parts (reliable only unless all_groups; only those without
    a misdescription or a forced level of detail with well_described)."""
    out = []
    for r in records:
        d = r.get("draw") or {}
        if well_described and (d.get("misdescription") is not None or d.get("fit_lod") is not None):
            continue
        res = r.get("result") or {}
        if res.get("error") or r.get("error") or res.get("range_k") is None or res.get("rho") is None:
            continue
        if res.get("range_stderr_stat") is None or res.get("rho_stderr_stat") is None:
            continue
        if all_groups or res.get("reliable"):
            out.append(r)
    return out


def stated(r: dict, floor: SystematicFloor) -> tuple[float, float]:
    res = r["result"]
    yk, yr = systematic_errors(res["range_k"], res["rho"], res.get("penumbra_px"), floor)
    return float(np.hypot(res["range_stderr_stat"], yk)), float(np.hypot(res["rho_stderr_stat"], yr))


def covered(r: dict, floor: SystematicFloor) -> tuple[bool, bool]:
    res = r["result"]
    sk, sr = stated(r, floor)
    ok_k = (abs(res["range_k"] - r["k_true"]) <= 2 * sk) if res.get("identifiable") else r["k_true"] <= res["range_k"]
    return bool(ok_k), bool(abs(res["rho"] - r["rho_true"]) <= 2 * sr)


def coverage(records: list[dict], floor: SystematicFloor) -> dict:
    cov = np.array([covered(r, floor) for r in records]) if records else np.zeros((0, 2), bool)
    errs = np.array([stated(r, floor) for r in records]) if records else np.zeros((0, 2))
    return {"groups": len(records), "k_coverage": round(float(cov[:, 0].mean()), 4) if len(cov) else None,
            "rho_coverage": round(float(cov[:, 1].mean()), 4) if len(cov) else None,
            "median_k_stderr_rel": round(float(np.median(errs[:, 0] / [r["result"]["range_k"] for r in records])), 4)
            if len(errs) else None,
            "median_rho_stderr": round(float(np.median(errs[:, 1])), 5) if len(errs) else None}


def calibrate(records: list[dict], target: float) -> SystematicFloor:
    """The floor on a grid that reaches ``target`` for k and for rho with the smallest mean log
    stated error (the k and rho parts are independent, so each is searched on its own)."""
    k_grid = [0.0, 0.02, 0.04, 0.06, 0.08, 0.10, 0.12, 0.15, 0.2, 0.25]
    px_grid = [0.0, 0.03, 0.06, 0.1, 0.15, 0.2, 0.3, 0.5]
    abs_grid = [0.0, 0.001, 0.002, 0.003, 0.005, 0.008, 0.012, 0.02]
    rel_grid = [0.0, 0.01, 0.02, 0.03, 0.05, 0.08, 0.12]

    def best(grid_a, grid_b, make, index):
        choice, width = None, np.inf
        for a, b in itertools.product(grid_a, grid_b):
            floor = make(a, b)
            if np.mean([covered(r, floor)[index] for r in records]) < target:
                continue
            w = np.mean([np.log(stated(r, floor)[index]) for r in records])
            if w < width:
                choice, width = (a, b), w
        if choice is None:
            raise SystemExit(f"no floor on the grid reaches {target:.0%} coverage")
        return choice

    ka, kb = best(k_grid, px_grid, lambda a, b: SystematicFloor(a, b, 0.0, 0.0), 0)
    ra, rb = best(abs_grid, rel_grid, lambda a, b: SystematicFloor(0.0, 0.0, a, b), 1)
    return SystematicFloor(ka, kb, ra, rb)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("study", type=Path, help="the study's JSON or a records.jsonl")
    ap.add_argument("--floor", type=float, nargs=4, metavar=("K_REL", "K_REL_PX", "RHO_ABS", "RHO_REL"),
                    help="a floor to try (default: the fitter's calibrated floor)")
    ap.add_argument("--calibrate", action="store_true", help="search the grid for the narrowest floor")
    ap.add_argument("--target", type=float, default=0.9, help="coverage the calibration aims at")
    ap.add_argument("--all-groups", action="store_true", help="every fitted group, not only the reliable")
    ap.add_argument("--well-described", action="store_true",
                    help="only the groups without a misdescription or a forced level of detail")
    args = ap.parse_args(argv)
    records = usable(read_records(args.study), args.all_groups, args.well_described)
    floor = SystematicFloor(*args.floor) if args.floor else CALIBRATED_FLOOR
    out = {"floor": floor._asdict(), "coverage": coverage(records, floor)}
    if args.calibrate:
        best = calibrate(records, args.target)
        out["calibrated_floor"] = best._asdict()
        out["with_calibrated_floor"] = coverage(records, best)
    print(json.dumps(out, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
