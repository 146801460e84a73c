"""The `street` preset measured without geometry, seed by seed; print JSON (and a Markdown table with --markdown).

Usage: nice -n 5 python examples/street_table.py [--seeds 0-11] [--size 640x480] [--root DIR] [--markdown]
           [--mitsuba DIR] [--records OUT.json] [--from-records IN.json] [--calibrate] [--target 0.9]

Each seed is rendered once into ROOT/street_<seed> (kept and reused when
--root is given) and measured with `fitting.fit_folder`, as `softshadow fit`
does. Per seed: the truth (open-ground rho and the umbra median rho_umbra),
the measured rho and stderr, its error against rho, the number of kept
profiles, reliable and the warnings, and whether the done-when criterion
holds: |rho - truth| <= 0.03, or reliable = false.

Coverage of the stated error (``coverage`` in the JSON): the fraction of seeds whose
truth rho lies within 2 stated rho_stderr, for all seeds and for the reliable ones,
and with the statistical part alone. ``--mitsuba DIR`` adds the photos of the Mitsuba
render folders there (each with truth.json), measured without geometry too (their
scene.toml is not read). ``--calibrate`` fits the systematic floor
(``fitting.solve.uncertainty.EdgeFloor``) to the rows: the smallest floor on a grid that puts
at least ``--target`` of the truths within 2 sigma. Calibrate on seeds that the
coverage run does not use (docs/uncertainty.md: calibration 100-111, coverage 0-11).
``--from-records`` recomputes the summary from saved rows without measuring again.
"""

from __future__ import annotations

import argparse
import itertools
import json
import tempfile
import time
from pathlib import Path

import numpy as np

from fitting.solve.uncertainty import CALIBRATED_EDGE_FLOOR, EdgeFloor, edge_rho_errors

TOLERANCE = 0.03


def _seeds(text: str) -> list[int]:
    out: list[int] = []
    for part in text.split(","):
        lo, _, hi = part.partition("-")
        out += list(range(int(lo), int(hi or lo) + 1))
    return out


def measure_seed(root: Path, seed: int, size: tuple[int, int]) -> dict:
    from data_synth import synthesize
    from fitting import fit_folder

    folder = root / f"street_{seed}"
    if not (folder / "truth.json").exists():
        synthesize(folder, "street", seed=seed, size=size, progress=False)
    truth = json.loads((folder / "truth.json").read_text())["groups"][0]
    start = time.process_time()
    (group,) = fit_folder(folder).groups
    cpu = time.process_time() - start
    rho = group.rho
    error = None if rho is None else rho - truth["rho"]
    ok = (error is not None and abs(error) <= TOLERANCE) or not group.reliable or rho is None
    return {"seed": seed, "sun_elevation_deg": truth.get("sun_elevation_deg"), "truth_rho": truth["rho"],
            "truth_rho_umbra": truth.get("rho_umbra"), "rho": rho, "rho_stderr": group.rho_stderr, "error": error,
            "rho_stderr_stat": group.rho_stderr_stat, "rho_stderr_sys": group.rho_stderr_sys,
            "spread_log": _spread(next(folder.glob("*.jpg"))) if rho is not None else None,
            "profiles": group.n_profiles, "reliable": group.reliable, "warnings": list(group.warnings),
            "criterion_met": bool(ok), "cpu_s": round(cpu, 2)}


def _measure(path: Path):
    from fitting import read_photo
    from fitting.edges.measure import measure_shadow_edges

    photo = read_photo(path)
    return measure_shadow_edges(photo.gray, mask=photo.excluded, linear_rgb=photo.linear)


def _spread(path: Path) -> float:
    """The kept profiles' log-rho spread of the photo (measured again, as `softshadow fit` does
    without geometry; results.json keeps only the errors it makes)."""
    from fitting.solve.uncertainty import profile_spread

    m = _measure(path)
    return profile_spread(np.log([p.rho for p in m.profiles if p.kept]))


def measure_mitsuba(folder: Path) -> list[dict]:
    """Rows for each photo of a Mitsuba render folder, measured without geometry."""
    from fitting.solve.uncertainty import profile_spread

    truth = json.loads((folder / "truth.json").read_text())["groups"][0]
    rows = []
    for name in truth["photos"]:
        start = time.process_time()
        m = _measure(folder / name)
        row = {"seed": f"mitsuba/{folder.name}", "truth_rho": truth["rho"], "truth_rho_umbra": None,
               "rho": None, "error": None, "profiles": m.n_profiles, "reliable": m.reliable,
               "warnings": list(m.warnings)}
        if m.edges_found:
            spread = profile_spread(np.log([p.rho for p in m.profiles if p.kept]))
            e = edge_rho_errors(m.rho, m.rho_stderr, spread)
            row.update(rho=m.rho, rho_stderr=e.rho_stderr, rho_stderr_stat=e.rho_stderr_stat,
                       rho_stderr_sys=e.rho_stderr_sys, spread_log=spread, error=m.rho - truth["rho"])
        row["criterion_met"] = bool(row["rho"] is None or not m.reliable or abs(row["error"]) <= TOLERANCE)
        row["cpu_s"] = round(time.process_time() - start, 2)
        rows.append(row)
    return rows


def _stated(row: dict, floor: EdgeFloor | None) -> float:
    """The row's stated error: as measured, or recomputed with ``floor`` from its statistical part."""
    if floor is None:
        return row["rho_stderr"]
    return edge_rho_errors(row["rho"], row["rho_stderr_stat"], row["spread_log"], floor).rho_stderr


def coverage(rows: list[dict], floor: EdgeFloor | None = None) -> dict:
    """Fractions of measured rows whose truth lies within 2 stated sigma (all, reliable, statistical only)."""
    got = [r for r in rows if r["rho"] is not None]

    def frac(sel, stat=False):
        ok = [abs(r["error"]) <= 2 * (r["rho_stderr_stat"] if stat else _stated(r, floor)) for r in sel]
        return round(float(np.mean(ok)), 3) if ok else None

    reliable = [r for r in got if r["reliable"]]
    return {"measured": len(got), "within_2_sigma": frac(got), "reliable": len(reliable),
            "within_2_sigma_reliable": frac(reliable), "within_2_sigma_statistical_only": frac(got, stat=True),
            "abs_z_median": round(float(np.median([abs(r["error"]) / _stated(r, floor) for r in got])), 2)
            if got else None,
            "rel_stderr_median": round(float(np.median([_stated(r, floor) / r["rho"] for r in got])), 4)
            if got else None}


def calibrate(rows: list[dict], target: float) -> EdgeFloor:
    """The floor on a grid that covers at least ``target`` of the rows within 2 sigma with the
    smallest mean log stated error."""
    got = [r for r in rows if r["rho"] is not None]
    best, width = None, np.inf
    for a, b, c in itertools.product([0.0, 0.002, 0.005], np.arange(0, 0.205, 0.01), np.arange(0, 2.05, 0.1)):
        floor = EdgeFloor(float(a), round(float(b), 3), round(float(c), 2))
        if coverage(got, floor)["within_2_sigma"] < target:
            continue
        w = float(np.mean([np.log(_stated(r, floor)) for r in got]))
        if w < width:
            best, width = floor, w
    if best is None:
        raise SystemExit(f"no floor on the grid reaches {target:.0%} coverage")
    return best


def _markdown(rows: list[dict]) -> str:
    lines = ["| seed | truth rho | rho_umbra | measured rho ± stderr | error | profiles | reliable | warnings |",
             "|---|---|---|---|---|---|---|---|"]
    for r in rows:
        val = "none" if r["rho"] is None else f"{r['rho']:.4f} ± {r['rho_stderr']:.4f}"
        err = "" if r["error"] is None else f"{r['error']:+.4f}"
        umbra = "" if r["truth_rho_umbra"] is None else f"{r['truth_rho_umbra']:.4f}"
        lines.append(f"| {r['seed']} | {r['truth_rho']:.4f} | {umbra} | {val} | {err} | {r['profiles']} | "
                     f"{'yes' if r['reliable'] else '**no**'} | {'; '.join(r['warnings'])} |")
    met = sum(r["criterion_met"] for r in rows)
    lines.append(f"\n{met} of {len(rows)} seeds meet the criterion (|error| <= {TOLERANCE}, or reliable = false).")
    return "\n".join(lines)


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", default="0-11")
    ap.add_argument("--size", default="640x480")
    ap.add_argument("--root", help="keep the rendered folders here (reused on the next run)")
    ap.add_argument("--markdown", action="store_true")
    ap.add_argument("--mitsuba", help="a folder of Mitsuba render folders (each with truth.json)")
    ap.add_argument("--records", help="save the rows here (JSON)")
    ap.add_argument("--from-records", help="summarise these saved rows instead of measuring")
    ap.add_argument("--calibrate", action="store_true", help="fit the systematic floor to the rows")
    ap.add_argument("--target", type=float, default=0.9)
    args = ap.parse_args(argv)
    size = tuple(int(v) for v in args.size.lower().split("x"))
    if args.from_records:
        rows = json.loads(Path(args.from_records).read_text())["rows"]
    else:
        with tempfile.TemporaryDirectory() as tmp:
            root = Path(args.root or tmp)
            root.mkdir(parents=True, exist_ok=True)
            rows = [measure_seed(root, s, size) for s in _seeds(args.seeds)]
        if args.mitsuba:
            for path in sorted(p for p in Path(args.mitsuba).iterdir() if (p / "truth.json").exists()):
                rows += measure_mitsuba(path)
    street = [r for r in rows if isinstance(r["seed"], int)]
    report = {"size": list(size), "rows": rows, "criterion_met": sum(r["criterion_met"] for r in street),
              "seeds": len(street), "floor": CALIBRATED_EDGE_FLOOR._asdict(),
              "coverage": {"street": coverage(street),
                           "mitsuba": coverage([r for r in rows if not isinstance(r["seed"], int)]),
                           "all": coverage(rows)}}
    if args.calibrate:
        floor = calibrate(rows, args.target)
        report["calibrated_floor"] = floor._asdict()
        report["coverage_with_calibrated_floor"] = coverage(rows, floor)
    if args.records:
        Path(args.records).write_text(json.dumps({"rows": rows}, indent=1))
    print(json.dumps(report, indent=1))
    if args.markdown:
        print(_markdown(street))


if __name__ == "__main__":
    main()
