"""The `street` preset measured without geometry, seed by seed; print JSON (and a Markdown table with --markdown).

Usage: nice -n 5 python examples/street_table.py [--seeds 0-11] [--size 640x480] [--root DIR] [--markdown]

Each seed is rendered once into ROOT/street_<seed> (kept and reused when
--root is given) and measured with `fitting.fit_folder`, as `softshadow fit`
does. Per seed: the truth (open-ground rho and the umbra median rho_umbra),
the measured rho and stderr, its error against rho, the number of kept
profiles, reliable and the warnings, and whether the done-when criterion
holds: |rho - truth| <= 0.03, or reliable = false.
"""

from __future__ import annotations

import argparse
import json
import tempfile
import time
from pathlib import Path

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
            "profiles": group.n_profiles, "reliable": group.reliable, "warnings": list(group.warnings),
            "criterion_met": bool(ok), "cpu_s": round(cpu, 2)}


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
    args = ap.parse_args(argv)
    size = tuple(int(v) for v in args.size.lower().split("x"))
    with tempfile.TemporaryDirectory() as tmp:
        root = Path(args.root or tmp)
        root.mkdir(parents=True, exist_ok=True)
        rows = [measure_seed(root, s, size) for s in _seeds(args.seeds)]
    print(json.dumps({"size": list(size), "rows": rows,
                      "criterion_met": sum(r["criterion_met"] for r in rows), "seeds": len(rows)}, indent=1))
    if args.markdown:
        print(_markdown(rows))


if __name__ == "__main__":
    main()
