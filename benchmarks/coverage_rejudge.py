"""The calibration study's records judged again by the rule book as it is now, without a refit.

A record fitted by ``benchmarks.coverage`` keeps what the rule book judged (``verdict_inputs``:
the group's ``FitEvidence`` and ``GroupContext`` as JSON). ``rejudge`` rebuilds them and calls
``fitting.verdict.rules.judge_fit`` again: the values, stated errors, ``reliable``,
``identifiable`` and warnings that the current rules give the same fit. What happens before the
verdict (the photos left out, the refit with the sun free, the sun search) is not re-run: a rule
that changes those needs a refit (``--refit``).

To guard against tuning the rules to the sample, compare the tables on the even and the odd
indices (``--half even`` / ``--half odd``)::

    python -m benchmarks.coverage_rejudge /tmp/softshadow-coverage-s0/records.jsonl --half even
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
from pathlib import Path

__all__ = ["evidence_from_json", "context_from_json", "rejudge", "rejudged", "main"]


def _tuple_pairs(items) -> tuple:
    return tuple(tuple(x) for x in items or ())


def _num(x):
    """JSON's null for a number the fit could not measure is NaN again."""
    return math.nan if x is None else x


def _with_gap(photo: dict) -> dict:
    """A photo's evidence with its ``depth_gap``: records fitted before the gap was measured sample
    by sample keep the difference of the two depths in its place."""
    if "depth_gap" in photo or photo.get("shadow_depth") is None or photo.get("predicted_depth") is None:
        return photo
    return {**photo, "depth_gap": photo["shadow_depth"] - photo["predicted_depth"]}


def evidence_from_json(d: dict):
    """A ``FitEvidence`` from ``dataclasses.asdict`` of one (as kept in a record)."""
    from fitting.verdict.evidence import FitEvidence, PhotoEvidence, SunFree
    d = dict(d)
    photo_fields = {f.name for f in dataclasses.fields(PhotoEvidence)}
    d["photos"] = tuple(PhotoEvidence(**{k: (_num(v) if k not in ("photo",) else v) for k, v in _with_gap(p).items()
                                         if k in photo_fields}) for p in d.get("photos", ()))
    d["photos_without_shadow"] = _tuple_pairs(d.get("photos_without_shadow"))
    if d.get("sun_free") is not None:
        d["sun_free"] = SunFree(**d["sun_free"])
    fields = {f.name for f in dataclasses.fields(FitEvidence)}
    return FitEvidence(**{k: v for k, v in d.items() if k in fields})


def context_from_json(d: dict | None):
    """A ``GroupContext`` from ``dataclasses.asdict`` of one (None: the default context)."""
    from fitting.verdict.evidence import GroupContext, LevelOfDetail, SunCheck
    if d is None:
        return GroupContext()
    d = dict(d)
    d["left_out"] = _tuple_pairs(d.get("left_out"))
    lod = {k: (_num(v) if k.startswith("shift") else v) for k, v in (d.get("level_of_detail") or {}).items()}
    d["level_of_detail"] = LevelOfDetail(**lod)
    if d.get("sun_check") is not None:
        check = dict(d["sun_check"])
        if check.get("path_deg_per_min") is not None:
            check["path_deg_per_min"] = tuple(check["path_deg_per_min"])
        d["sun_check"] = SunCheck(**check)
    fields = {f.name for f in dataclasses.fields(GroupContext)}
    return GroupContext(**{k: v for k, v in d.items() if k in fields})


def rejudge(record: dict, floor=None) -> dict:
    """The record with its result's verdict fields as the current rule book gives them (unchanged
    when it kept no ``verdict_inputs``: a group with an error, or fitted before they were kept).
    floor: a ``fitting.solve.uncertainty.SystematicFloor`` to state the systematic errors with
    instead of the one the fit used."""
    from fitting.solve.uncertainty import systematic_errors
    from fitting.verdict.rules import judge_fit
    inputs = record.get("verdict_inputs")
    if not inputs or (record.get("result") or {}).get("error"):
        return record
    fit = evidence_from_json(inputs["evidence"])
    if floor is not None:
        k_sys, rho_sys = systematic_errors(fit.k, fit.rho, fit.penumbra_px, floor)
        fit = dataclasses.replace(fit, k_stderr_sys=k_sys, rho_stderr_sys=rho_sys)
    estimate, verdict = judge_fit(fit, context_from_json(inputs.get("context")))
    result = dict(record["result"])
    result.update({"range_k": estimate.range_k, "rho": estimate.rho, "range_stderr": estimate.range_stderr,
                   "rho_stderr": estimate.rho_stderr, "range_stderr_stat": estimate.range_stderr_stat,
                   "rho_stderr_stat": estimate.rho_stderr_stat, "range_stderr_sys": estimate.range_stderr_sys,
                   "rho_stderr_sys": estimate.rho_stderr_sys, "reliable": verdict.reliable,
                   "identifiable": verdict.identifiable, "warnings": list(verdict.warnings)})
    return {**record, "result": result}


def rejudged(records: list[dict], floor=None) -> list[dict]:
    return [rejudge(r, floor) for r in records]


def _read(path: Path) -> list[dict]:
    from .coverage import _latest, read_records
    if path.suffix == ".json":
        return _latest(json.loads(path.read_text())["records"])
    return _latest(read_records(path))


def _row(name: str, records: list[dict]) -> str:
    from .coverage_tables import summarize
    s = summarize(records)
    return (f"{name:15s} groups {s['groups']:3d} reliable {s['reliable']:3d} k {s['k_covered']}/{s['reliable']} "
            f"rho {s['rho_covered']}/{s['reliable']} bounds {s['k_bounds']} flagged {s['flagged']} "
            f"misses {s['confident_misses']} well described flagged {s['well_described_flagged']}/"
            f"{s['well_described']} (false alarms {s['false_alarms']})")


def table(records: list[dict]) -> list[str]:
    """One line each for all groups, the well described and the misdescribed."""
    from .coverage_tables import well_described
    well = [r for r in records if well_described(r.get("draw") or {})]
    mis = [r for r in records if not well_described(r.get("draw") or {})]
    return [_row("all", records), _row("well described", well), _row("misdescribed", mis)]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("records", type=Path, help="records.jsonl or a study JSON")
    ap.add_argument("--half", choices=("all", "even", "odd"), default="all")
    ap.add_argument("--json", type=Path, help="write the re-judged study JSON here")
    ap.add_argument("--floor", help="k_rel,k_rel_px,rho_abs,rho_rel: state the systematic errors with this floor")
    args = ap.parse_args(argv)
    records = [r for r in _read(args.records)
               if args.half == "all" or r["index"] % 2 == (0 if args.half == "even" else 1)]
    kept = [r for r in records if r.get("verdict_inputs")]
    print(f"{len(records)} records, {len(kept)} with the rule book's inputs")
    print("as recorded:", *table(records), sep="\n  ")
    floor = None
    if args.floor:
        from fitting.solve.uncertainty import SystematicFloor
        floor = SystematicFloor(*(float(x) for x in args.floor.split(",")))
    after = rejudged(records, floor)
    print("re-judged:", *table(after), sep="\n  ")
    if args.json:
        from .coverage import assemble
        args.json.write_text(json.dumps(assemble(after, records[0]["seed"] if records else 0), indent=1) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
