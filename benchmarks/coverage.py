"""``softshadow bench --what coverage``: do the stated errors cover the truth off the presets?

Each group is drawn at random from a documented prior (``data_synth.draw.ScenePrior``; the
study adds the real dragon to its meshes), rendered by ``data_synth``'s physical renderer
(ray-cast sun disk and sky, independent of the fitted model) into its own folder, fitted
with the default options (plus a forced level of detail where the draw says so) and
compared with its truth. Group ``i`` of seed ``S`` is drawn from
``numpy.random.default_rng([S, i])``, so any group is re-made alone.

Records go to ``ROOT/records.jsonl`` as each group finishes (a stopped run resumes where
it stopped; ``refit`` fits the kept folders again, for a new verdict). The JSON written at
the end holds the environment, the prior, every record (draw, truth, result) and the
tables (``coverage_tables``); the Markdown report (``coverage_report``) is made from that
JSON alone.

Re-make one group's folder (and print the fit command)::

    python -m benchmarks.coverage --seed 0 --index 17 --out /tmp/group17
"""

from __future__ import annotations

import argparse
import contextlib
import json
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

__all__ = ["STUDY_MESHES", "study_prior", "study_meshes", "group_draw", "synth_group", "fit_group",
           "study_record", "run_coverage", "parse_indices", "read_records", "assemble", "main"]

STUDY_MESHES = ("pillar", "ball", "knot", "dragon")
RECORDS_FILE = "records.jsonl"
#: The result fields a record keeps: the contract's, then extras for reading a failure.
RESULT_FIELDS = ("label", "photos", "range_k", "range_stderr", "rho", "rho_stderr", "reliable", "identifiable",
                 "warnings", "error", "range_stderr_stat", "range_stderr_sys", "rho_stderr_stat", "rho_stderr_sys",
                 "sun_azimuth_deg", "sun_elevation_deg", "sun_source", "penumbra_px", "blur_px", "n_profiles",
                 "n_samples", "rmse", "lod_faces", "mesh_faces", "profile", "converged", "seconds")


def study_prior():
    """The study's prior: data_synth's default with the real dragon among the meshes."""
    from data_synth.draw import ScenePrior
    return ScenePrior(meshes=STUDY_MESHES)


def study_meshes() -> dict:
    """The meshes that are not built in: the real dragon (the bench's vendored MIT dragon, 26,584 faces)."""
    from .meshes import mit_dragon
    return {"dragon": mit_dragon()}


def group_draw(seed: int, index: int, prior=None, meshes=None):
    """Group ``index`` of seed ``seed``: a ``SceneDraw`` from ``default_rng([seed, index])``."""
    from data_synth.draw import draw_parameters
    return draw_parameters(np.random.default_rng([int(seed), int(index)]), prior or study_prior(),
                           meshes if meshes is not None else study_meshes())


def _folder(root: Path, seed: int, index: int) -> Path:
    return Path(root) / f"s{seed}-g{index:04d}"


def synth_group(seed: int, index: int, root, prior=None, meshes=None, render_quality=None):
    """(folder, draw) of a group, rendered unless the folder already holds this very draw."""
    from data_synth.draw import synthesize_draw
    meshes = meshes if meshes is not None else study_meshes()
    draw = group_draw(seed, index, prior, meshes)
    folder = _folder(Path(root), seed, index)
    truth = folder / "truth.json"
    if truth.exists():
        with contextlib.suppress(ValueError, OSError):
            if json.loads(truth.read_text()).get("draw") == json.loads(json.dumps(draw.to_json())):
                return folder, draw
    synthesize_draw(draw, folder, meshes=meshes, render_quality=render_quality, force=True)
    return folder, draw


@contextlib.contextmanager
def _verdict_inputs():
    """Keep what the rule book judged: the (evidence, context) of each final ``judge_fit`` call,
    by the evidence's id, so that a record can be judged again by changed rules without a refit
    (``coverage_rejudge``)."""
    from fitting.verdict import rules
    seen: dict[int, tuple] = {}
    judge = rules.judge_fit

    def keeping(fit, context=None):
        seen[id(fit)] = (fit, context)
        return judge(fit, context)
    rules.judge_fit = keeping
    try:
        yield seen
    finally:
        rules.judge_fit = judge


def fit_group(folder, draw) -> dict:
    """Fit a group's folder with the default options (and the draw's forced level of detail):
    the result group that holds the truth's photos (its RESULT_FIELDS), the photos skipped,
    how many groups the fit found, and what the rule book judged (``verdict_inputs``: the
    evidence and context as JSON, None for a group with an error)."""
    import dataclasses
    from fitting import FitOptions, FolderError, fit_folder
    options = FitOptions(plots=False)
    if draw.fit_lod is not None:
        options.lod = int(draw.fit_lod)
    truth = json.loads((Path(folder) / "truth.json").read_text())
    photos = set(truth["groups"][0]["photos"])
    try:
        with _verdict_inputs() as seen:
            results = fit_folder(folder, options=options)
    except FolderError as exc:
        return {"result": {"error": f"folder: {exc}", "reliable": False, "identifiable": False},
                "skipped": [], "result_groups": 0}
    best = max(results.groups, key=lambda g: len(photos & set(g.photos)), default=None)
    inputs = None
    if best is None or not photos & set(best.photos):
        result = {"error": "no group holds the drawn photos", "reliable": False, "identifiable": False}
    else:
        as_json = best.to_json()
        result = {k: as_json.get(k) for k in RESULT_FIELDS if k in as_json}
        judged = seen.get(id(best.evidence)) if best.evidence is not None else None
        if judged is not None:
            inputs = {"evidence": dataclasses.asdict(judged[0]),
                      "context": dataclasses.asdict(judged[1]) if judged[1] is not None else None}
    return {"result": result, "skipped": list(results.skipped), "result_groups": len(results.groups),
            "verdict_inputs": inputs}


def _truth_fields(folder: Path) -> dict:
    truth = json.loads((folder / "truth.json").read_text())
    g = truth["groups"][0]
    px = [d["penumbra_px"] for d in truth["photos_detail"].values()]
    az = np.radians([d["sun_azimuth_deg"] for d in truth["photos_detail"].values()])
    mean_az = float(np.degrees(np.arctan2(np.sin(az).mean(), np.cos(az).mean())) % 360.0) if len(az) else None
    return {"k_true": g["range_k"], "rho_true": g["rho"], "sun_azimuth_true": mean_az,
            "sun_elevation_true": g["sun_elevation_deg"], "truth_penumbra_px": float(np.median(px)) if px else None,
            "photos_true": list(g["photos"])}


def study_record(seed: int, index: int, root, prior=None, meshes=None, render_quality=None) -> dict:
    """One group: draw, render (or reuse), fit, and the record (draw, truth, result, timings).
    A failure to render or fit is recorded (``error``), never raised."""
    from .environment import load_average
    record = {"seed": int(seed), "index": int(index)}
    t0 = time.perf_counter()
    try:
        folder, draw = synth_group(seed, index, root, prior, meshes, render_quality)
        record["draw"] = draw.to_json()
        record["folder"] = str(folder)
        record.update(_truth_fields(folder))
    except Exception as exc:  # noqa: BLE001  a study records every failure and goes on
        record["error"] = f"synthesis: {type(exc).__name__}: {exc}"
        record["draw"] = group_draw(seed, index, prior, meshes).to_json()
        return record
    t1 = time.perf_counter()
    try:
        record.update(fit_group(folder, draw))
    except Exception as exc:  # noqa: BLE001
        record["error"] = f"fit: {type(exc).__name__}: {exc}"
        record["result"] = {"error": record["error"], "reliable": False, "identifiable": False}
    record["seconds_synth"] = round(t1 - t0, 1)
    record["seconds_fit"] = round(time.perf_counter() - t1, 1)
    record["load_average"] = load_average()
    record["finished_utc"] = time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime())
    record["commit"] = _commit()
    return record


def parse_indices(text: str | None) -> list[int] | None:
    """'3,17,40-45' -> [3, 17, 40, ..., 45]; None stays None."""
    if not text:
        return None
    out = []
    for part in str(text).split(","):
        a, _, b = part.strip().partition("-")
        out += list(range(int(a), int(b) + 1)) if b else [int(a)]
    return out


def read_records(path) -> list[dict]:
    """The records of a records.jsonl (a line cut by a stopped run is ignored)."""
    out = []
    p = Path(path)
    if not p.exists():
        return out
    for line in p.read_text().splitlines():
        with contextlib.suppress(ValueError):
            out.append(json.loads(line))
    return out


def _line(record: dict) -> str:
    from .coverage_tables import judge
    d = record.get("draw", {})
    j = judge(record)
    r = record.get("result") or {}

    def pull(x):
        return "-" if x is None else f"{x:+.1f}"
    what = (f"g{record['index']:04d} {d.get('mesh')} {d.get('receiver_shape')} {d.get('width')}x{d.get('height')} "
            f"x{len(d.get('photo_draws', []))} el {d.get('sun_elevation_deg', 0):.0f} {d.get('sun_source')} "
            f"{d.get('misdescription') or ('lod' if d.get('fit_lod') else 'ok')}")
    if record.get("error") or r.get("error"):
        return f"{what}: ERROR {record.get('error') or r.get('error')}"
    return (f"{what}: k pull {pull(j.k_pull)}{'' if j.identifiable else ' (bound)'} rho pull {pull(j.rho_pull)} "
            f"{'reliable' if j.reliable else 'flagged'}{' CONFIDENT MISS' if j.confident_miss else ''} "
            f"({record.get('seconds_synth')} + {record.get('seconds_fit')} s)")


def _commit() -> str | None:
    with contextlib.suppress(OSError, subprocess.SubprocessError):
        out = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=Path(__file__).parent, capture_output=True,
                             text=True, timeout=10)
        return out.stdout.strip() or None
    return None


def run_coverage(groups: int = 300, seed: int = 0, root=None, *, only: list[int] | None = None,
                 refit: bool = False, progress=None, render_quality=None) -> list[dict]:
    """Draw, render, fit and record groups 0..groups-1 of ``seed`` (or ``only`` those), appending
    each record to ROOT/records.jsonl as it finishes; groups already recorded are kept unless
    ``refit`` (then their folders are fitted again). Returns the records of the groups asked for."""
    root = Path(root or f"/tmp/softshadow-coverage-s{seed}")
    root.mkdir(parents=True, exist_ok=True)
    path = root / RECORDS_FILE
    wanted = list(range(groups)) if only is None else list(only)
    kept = {(r["seed"], r["index"]): r for r in read_records(path)}
    prior, meshes = study_prior(), study_meshes()
    out = []
    for index in wanted:
        key = (int(seed), int(index))
        if key in kept and not refit:
            out.append(kept[key])
            continue
        record = study_record(seed, index, root, prior, meshes, render_quality)
        with path.open("a") as f:
            f.write(json.dumps(record) + "\n")
        kept[key] = record
        out.append(record)
        if progress:
            progress(_line(record))
    return out


def _latest(records: list[dict]) -> list[dict]:
    """The last record of each (seed, index), in index order."""
    by = {}
    for r in records:
        by[(r["seed"], r["index"])] = r
    return [by[k] for k in sorted(by)]


def assemble(records: list[dict], seed: int, environment: dict | None = None) -> dict:
    """The study's JSON: environment, prior, records and tables (everything the report needs)."""
    from .coverage_tables import FACTORS, bin_table, criteria, summarize
    records = _latest(records)
    return {
        "environment": environment or {},
        "commit": _commit(),
        "seed": int(seed),
        "prior": study_prior().to_json(),
        "definitions": {
            "flagged": "reliable is false, or the group has no values (an error)",
            "k covered": "|k - k_true| <= 2 range_stderr; when not identifiable, k_true <= range_k (a bound)",
            "rho covered": "|rho - rho_true| <= 2 rho_stderr",
            "coverage": "among the groups reported reliable",
            "confident miss": "reliable, and k or rho beyond 3 stated sigma (a bound: the truth above it by more "
                              "than one range_stderr); its share is among all groups",
            "false alarm": "a well-described group (no misdescription, no forced level of detail) that is flagged "
                           "although its k and rho were within their stated errors; the flags on well-described "
                           "groups whose values were off are counted apart (flagged rightly)",
        },
        "summary": summarize(records),
        "bins": {factor: bin_table(records, factor) for factor in FACTORS},
        "criteria": criteria(records),
        "records": records,
    }


def coverage_and_report(args, progress=None) -> dict:
    """The bench entry: run (or read ``--from-json``), assemble, write ``--json`` and ``--report``."""
    import datetime
    from .environment import environment, load_average
    seed = int(getattr(args, "seed", 0) or 0)
    if getattr(args, "from_json", None):
        result = json.loads(Path(args.from_json).read_text())
        result.update({k: v for k, v in assemble(result["records"], result.get("seed", seed),
                                                 result.get("environment")).items() if k != "commit"})
    else:
        env = environment()
        t0 = time.perf_counter()
        records = run_coverage(int(getattr(args, "groups", None) or 300), seed, getattr(args, "root", None),
                               only=parse_indices(getattr(args, "only", None)), refit=bool(getattr(args, "refit", False)),
                               progress=progress)
        env["load_average_at_end"] = load_average()
        env["run_minutes"] = round((time.perf_counter() - t0) / 60.0, 1)
        env["finished_utc"] = datetime.datetime.now(datetime.UTC).strftime("%Y-%m-%d %H:%M UTC")
        if getattr(args, "only", None) is None:
            root = Path(getattr(args, "root", None) or f"/tmp/softshadow-coverage-s{seed}")
            records = [r for r in _latest(read_records(root / RECORDS_FILE)) if r["seed"] == seed]
        result = assemble(records, seed, env)
    if getattr(args, "json_path", None):
        Path(args.json_path).parent.mkdir(parents=True, exist_ok=True)
        Path(args.json_path).write_text(json.dumps(result, indent=1) + "\n")
    if getattr(args, "report", None):
        from .coverage_report import write_coverage_report
        write_coverage_report(json.loads(json.dumps(result)), Path(args.report),
                              Path(args.json_path).name if getattr(args, "json_path", None) else None)
    return result


def main(argv=None) -> int:
    """Re-make one group's folder: ``python -m benchmarks.coverage --seed S --index I --out DIR [--fit]``."""
    ap = argparse.ArgumentParser(description="Re-make one group of the coverage study (and optionally fit it).")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--index", type=int, required=True)
    ap.add_argument("--out", required=True, help="the folder to write (re-used when it holds this draw)")
    ap.add_argument("--fit", action="store_true", help="also fit it and print the record")
    args = ap.parse_args(argv)
    from data_synth.draw import synthesize_draw
    meshes = study_meshes()
    draw = group_draw(args.seed, args.index, meshes=meshes)
    folder = synthesize_draw(draw, args.out, meshes=meshes, force=True)
    lod = f" --lod {draw.fit_lod}" if draw.fit_lod is not None else ""
    print(f"{folder}: softshadow fit {folder} --out {folder}/fit{lod}")
    if args.fit:
        record = {"seed": args.seed, "index": args.index, "draw": draw.to_json(), **_truth_fields(Path(folder)),
                  **fit_group(folder, draw)}
        print(json.dumps(record, indent=1))
        print(_line(record))
    return 0


if __name__ == "__main__":
    sys.exit(main())
