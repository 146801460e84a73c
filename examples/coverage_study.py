"""Do the stated one-sigma errors cover the truth? Synthesise physical folders, fit them, print JSON.

Usage:
    nice -n 5 python examples/coverage_study.py [--root DIR] [--seeds 0-29] [--mitsuba DIR]
        [--records OUT.json] [--from-records IN.json] [--calibrate]

Each folder is a ``data_synth`` preset (physical renderer: ray-cast sun disk and sky,
independent of the fitted model) at a seed, cycling through presets (table2: three
times of day; pillar, ball, dragon: 10:30) and image sizes (640x480, 800x600,
1024x768); synthesised into ``--root`` once and reused. ``--mitsuba`` adds the
Mitsuba 3 renders (folders with truth.json). Every group is fitted with the
default options and compared with its truth:

- k is covered when |k - k_true| <= 2 range_stderr; for a group whose range is not
  identifiable (range_k is an upper bound) when k_true <= range_k;
- rho is covered when |rho - rho_true| <= 2 rho_stderr.

``--calibrate`` fits the systematic floor (``fitting.solve.uncertainty.SystematicFloor``) to
the records: the smallest floor (on a grid) that covers at least ``--target`` of the
k and rho values within 2 sigma. Calibrate on seeds that the coverage study does not
use (the defaults: calibration 1000-1011, coverage 0-29). ``--from-records`` recomputes
the summary from saved records (their statistical parts) without refitting.
"""

from __future__ import annotations

import argparse
import itertools
import json
import sys
import time
from pathlib import Path

import numpy as np

from fitting import FitOptions, FolderError, fit_folder
from fitting.solve.uncertainty import CALIBRATED_FLOOR, SystematicFloor, systematic_errors

PRESET_CYCLE = ("table2", "pillar", "ball", "dragon")
SIZE_CYCLE = ((640, 480), (800, 600), (1024, 768))


def parse_seeds(text: str) -> list[int]:
    """'0-29' or '1,2,5' or '0-3,7' -> list of ints."""
    out = []
    for part in text.split(","):
        a, _, b = part.partition("-")
        out += list(range(int(a), int(b) + 1)) if b else [int(a)]
    return out


def folder_plan(seed: int) -> tuple[str, tuple[int, int]]:
    """The preset and size of a seed: presets cycle fastest, sizes next."""
    return PRESET_CYCLE[seed % len(PRESET_CYCLE)], SIZE_CYCLE[(seed // len(PRESET_CYCLE)) % len(SIZE_CYCLE)]


def synth_folder(root: Path, seed: int) -> Path:
    from data_synth import synthesize
    preset, size = folder_plan(seed)
    path = root / f"{preset}-s{seed}-{size[0]}x{size[1]}"
    if not (path / "truth.json").exists():
        synthesize(path, preset=preset, seed=seed, renderer="physical", size=size, force=True, progress=False)
    return path


def _truth_for(group: dict, truth: dict) -> dict | None:
    photos = set(group["photos"])
    for t in truth["groups"]:
        if photos & set(t.get("photos", [])):
            return t
    return truth["groups"][0] if len(truth["groups"]) == 1 else None


def fit_records(path: Path, source: str) -> list[dict]:
    """One record per fitted group of a folder: the fit's values and error parts beside the truth."""
    truth = json.loads((path / "truth.json").read_text())
    t0 = time.perf_counter()
    try:
        results = fit_folder(path, options=FitOptions(plots=False))
    except FolderError as exc:
        return [{"folder": path.name, "source": source, "error": str(exc)}]
    out = []
    for g in results.groups:
        j = g.to_json()
        t = _truth_for(j, truth)
        rec = {"folder": path.name, "source": source, "label": j["label"], "seconds": round(time.perf_counter() - t0, 1)}
        if t is None or not g.fitted:
            rec["error"] = j.get("error") or "no truth for this group"
            out.append(rec)
            continue
        rec.update({k: j.get(k) for k in ("range_k", "range_stderr", "range_stderr_stat", "rho", "rho_stderr",
                                          "rho_stderr_stat", "penumbra_px", "identifiable", "reliable",
                                          "warnings", "n_profiles")})
        rec.update({"k_true": float(t["range_k"]), "rho_true": float(t["rho"])})
        out.append(rec)
    return out


def stated(rec: dict, floor: SystematicFloor | None) -> tuple[float, float]:
    """The record's stated errors: as fitted, or recomputed with ``floor`` from the statistical
    parts (the floor does not change the fit itself, so records fitted with another floor serve)."""
    if floor is None:
        return rec["range_stderr"], rec["rho_stderr"]
    yk, yr = systematic_errors(rec["range_k"], rec["rho"], rec["penumbra_px"], floor)
    return float(np.hypot(rec["range_stderr_stat"], yk)), float(np.hypot(rec["rho_stderr_stat"], yr))


def covered(rec: dict, floor: SystematicFloor | None = CALIBRATED_FLOOR) -> tuple[bool, bool]:
    sk, sr = stated(rec, floor)
    if rec["identifiable"]:
        ok_k = abs(rec["range_k"] - rec["k_true"]) <= 2 * sk
    else:
        ok_k = rec["k_true"] <= rec["range_k"]
    return bool(ok_k), bool(abs(rec["rho"] - rec["rho_true"]) <= 2 * sr)


def summary(records: list[dict], floor: SystematicFloor | None = CALIBRATED_FLOOR) -> dict:
    fitted = [r for r in records if "error" not in r]
    cov = [covered(r, floor) for r in fitted]
    ident = [r for r in fitted if r["identifiable"]]

    def frac(xs):
        return round(float(np.mean(xs)), 3) if len(xs) else None

    def z(r, which):
        sk, sr = stated(r, floor)
        if which == "k":
            return (r["range_k"] - r["k_true"]) / sk
        return (r["rho"] - r["rho_true"]) / sr

    def stat_z(r, which):
        if which == "k":
            return (r["range_k"] - r["k_true"]) / r["range_stderr_stat"]
        return (r["rho"] - r["rho_true"]) / r["rho_stderr_stat"]

    reliable = [c for r, c in zip(fitted, cov) if r["reliable"]]
    return {
        "groups": len(records), "fitted": len(fitted), "failed": len(records) - len(fitted),
        "folders": len({r["folder"] for r in records}),
        "k_within_2_sigma": frac([c[0] for c in cov]), "rho_within_2_sigma": frac([c[1] for c in cov]),
        "k_within_2_sigma_statistical_only": frac([abs(stat_z(r, "k")) <= 2 for r in ident]),
        "rho_within_2_sigma_statistical_only": frac([abs(stat_z(r, "rho")) <= 2 for r in fitted]),
        "reliable_groups": len(reliable),
        "k_within_2_sigma_reliable": frac([c[0] for c in reliable]),
        "rho_within_2_sigma_reliable": frac([c[1] for c in reliable]),
        "not_identifiable": len(fitted) - len(ident),
        "k_abs_z_median": round(float(np.median([abs(z(r, "k")) for r in ident])), 2) if ident else None,
        "rho_abs_z_median": round(float(np.median([abs(z(r, "rho")) for r in fitted])), 2) if fitted else None,
        "k_rel_error_median": round(float(np.median([abs(r["range_k"] / r["k_true"] - 1) for r in ident])), 4)
        if ident else None,
        "k_rel_stderr_median": round(float(np.median([stated(r, floor)[0] / r["range_k"] for r in ident])), 4)
        if ident else None,
        "rho_abs_error_median": round(float(np.median([abs(r["rho"] - r["rho_true"]) for r in fitted])), 4)
        if fitted else None,
        "rho_stderr_median": round(float(np.median([stated(r, floor)[1] for r in fitted])), 4) if fitted else None,
    }


def calibrate(records: list[dict], target: float) -> SystematicFloor:
    """The floor on a grid that reaches ``target`` coverage for k and for rho with the smallest
    mean log stated error (k and rho are calibrated separately: their floors are independent)."""
    fitted = [r for r in records if "error" not in r]
    k_grid = [0.0, 0.01, 0.02, 0.03, 0.04, 0.05, 0.06, 0.08, 0.10, 0.12, 0.15]
    px_grid = [0.0, 0.02, 0.04, 0.06, 0.08, 0.10, 0.12, 0.15, 0.2, 0.25, 0.3]
    abs_grid = [0.0, 0.001, 0.002, 0.003, 0.004, 0.005, 0.006, 0.008, 0.010, 0.012, 0.015]
    rel_grid = [0.0, 0.01, 0.02, 0.03, 0.04, 0.05, 0.06, 0.08, 0.10]

    def best(grid_a, grid_b, make, index):
        choice, width = None, np.inf
        for a, b in itertools.product(grid_a, grid_b):
            floor = make(a, b)
            cov = np.mean([covered(r, floor)[index] for r in fitted])
            if cov < target:
                continue
            w = np.mean([np.log(stated(r, floor)[index]) for r in fitted])
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
    ap.add_argument("--root", default="/tmp/softshadow-coverage", help="where the synthetic folders go")
    ap.add_argument("--seeds", default="0-29", help="data_synth seeds, e.g. 0-29 or 1000-1011")
    ap.add_argument("--mitsuba", default=None, help="a folder of Mitsuba render folders (each with truth.json)")
    ap.add_argument("--records", default=None, help="write every group's record to this JSON file")
    ap.add_argument("--from-records", default=None, help="read records from this JSON file instead of fitting")
    ap.add_argument("--calibrate", action="store_true", help="fit the systematic floor to the records")
    ap.add_argument("--target", type=float, default=0.95, help="coverage the calibration aims at")
    args = ap.parse_args(argv)
    if args.from_records:
        records = json.loads(Path(args.from_records).read_text())
    else:
        root = Path(args.root)
        root.mkdir(parents=True, exist_ok=True)
        records = []
        for seed in parse_seeds(args.seeds):
            records += fit_records(synth_folder(root, seed), "data_synth physical")
            print(f"seed {seed}: {len(records)} groups", file=sys.stderr, flush=True)
        if args.mitsuba:
            for path in sorted(p for p in Path(args.mitsuba).iterdir() if (p / "truth.json").exists()):
                records += fit_records(path, "mitsuba")
        if args.records:
            Path(args.records).write_text(json.dumps(records, indent=1))
    out = {"floor": CALIBRATED_FLOOR._asdict(), "all": summary(records)}
    for source in sorted({r["source"] for r in records}):
        out[source] = summary([r for r in records if r["source"] == source])
    if args.calibrate:
        floor = calibrate(records, args.target)
        out["calibrated_floor"] = floor._asdict()
        out["with_calibrated_floor"] = summary(records, floor)
    print(json.dumps(out, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
