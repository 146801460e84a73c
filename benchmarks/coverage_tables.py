"""The calibration study's tables, from its records alone (no fitting): pure functions.

A record is one drawn group: its draw (``data_synth.draw.SceneDraw.to_json``), its truth
(``k_true``, ``rho_true``) and the fit's result (the results.json fields ``range_k``,
``range_stderr``, ``rho``, ``rho_stderr``, ``reliable``, ``identifiable``, ``warnings``,
``error``). ``judge`` reads one record; ``summarize`` counts them overall and per factor bin.

Definitions (docs/uncertainty_study.md repeats them):

- **flagged**: the group is not reported reliable, or has no values (an error);
- **k covered**: |k - k_true| <= 2 stated sigma; for a k that is not identifiable (range_k
  an upper bound) k_true <= range_k;
- **rho covered**: |rho - rho_true| <= 2 stated sigma;
- coverage is counted among the groups reported reliable;
- **confident miss**: reliable, and k or rho beyond 3 stated sigma of the truth (for a bound:
  the truth above the bound by more than one stated sigma, the bound being k + 2 sigma);
- **false alarm**: a well-described group (no misdescription, no forced level of detail)
  that is flagged although its k and rho were within their stated errors: the flag had nothing
  to find. A flagged well-described group whose values were off is flagged rightly (the data or
  the model could not give the values); both are counted (``well_described_flagged``).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Iterable

__all__ = ["Judgement", "judge", "FACTORS", "factor_bin", "summarize", "bin_table", "criteria",
           "COVERAGE_TARGET", "MIN_RELIABLE_PER_BIN", "MAX_CONFIDENT_MISSES", "MAX_FALSE_ALARMS", "MIN_GROUPS"]

#: The study's targets (issue 24's "done when").
COVERAGE_TARGET = 0.90
MIN_RELIABLE_PER_BIN = 20
MAX_CONFIDENT_MISSES = 0.01
MAX_FALSE_ALARMS = 0.05
#: The issue asks for a study of at least this many groups.
MIN_GROUPS = 300


@dataclasses.dataclass(frozen=True)
class Judgement:
    """One group against its truth. pulls are (value - truth) / stated sigma (None for a bound or
    no value); k_covered / rho_covered are None when the group is flagged (not counted)."""

    fitted: bool
    reliable: bool
    identifiable: bool
    flagged: bool
    well_described: bool
    k_covered: bool | None
    rho_covered: bool | None
    confident_miss: bool
    k_pull: float | None
    rho_pull: float | None
    k_miss_kind: str | None  # "low", "high", "above bound" when not covered
    values_covered: bool | None  # k and rho within their stated errors, reliable or not (None: no values)


def _num(x) -> float | None:
    if x is None:
        return None
    try:
        x = float(x)
    except (TypeError, ValueError):
        return None
    return x if math.isfinite(x) else None


def _pull(value, truth, sigma) -> float | None:
    value, truth, sigma = _num(value), _num(truth), _num(sigma)
    if value is None or truth is None:
        return None
    if sigma is None or sigma <= 0:
        return math.inf if value != truth else 0.0
    return (value - truth) / sigma


def well_described(draw: dict) -> bool:
    """No misdescription and no forced level of detail."""
    return draw.get("misdescription") is None and draw.get("fit_lod") is None


def judge(record: dict) -> Judgement:
    """Judge one record (see the module's definitions)."""
    r = record.get("result") or {}
    draw = record.get("draw") or {}
    k, rho = _num(r.get("range_k")), _num(r.get("rho"))
    fitted = not r.get("error") and not record.get("error") and k is not None and rho is not None
    reliable = bool(r.get("reliable")) and fitted
    identifiable = bool(r.get("identifiable")) and fitted
    flagged = not reliable
    k_true, rho_true = record.get("k_true"), record.get("rho_true")
    sk = _num(r.get("range_stderr"))
    k_pull = _pull(k, k_true, sk) if fitted and identifiable else None
    rho_pull = _pull(rho, rho_true, r.get("rho_stderr")) if fitted else None
    k_cov = rho_cov = values = None
    miss = False
    kind = None
    if fitted:
        if identifiable:
            k_ok = abs(k_pull) <= 2.0
            k_bad = abs(k_pull) > 3.0
            if not k_ok:
                kind = "high" if k_pull > 0 else "low"
        else:
            k_ok = k_true <= k
            k_bad = k_true > k + (sk or 0.0)
            if not k_ok:
                kind = "above bound"
        rho_ok = abs(rho_pull) <= 2.0
        values = bool(k_ok and rho_ok)
        if reliable:
            k_cov, rho_cov = bool(k_ok), bool(rho_ok)
            miss = bool(k_bad or abs(rho_pull) > 3.0)
    return Judgement(fitted, reliable, identifiable, flagged, well_described(draw), k_cov, rho_cov, miss,
                     k_pull, rho_pull, kind, values)


def _edges_bin(value: float, edges: tuple[float, ...], fmt: Callable[[float], str]) -> str:
    """The bin 'lo-hi' of value among consecutive edges (values beyond the ends go to the end bins)."""
    i = 0
    while i < len(edges) - 2 and value >= edges[i + 1]:
        i += 1
    return f"{fmt(edges[i])}-{fmt(edges[i + 1])}"


def _mp(draw) -> float:
    return draw["width"] * draw["height"] / 1e6


def _misdescribed(draw: dict) -> str:
    if draw.get("fit_lod") is not None:
        return "forced level of detail"
    kind = draw.get("misdescription")
    return {None: "well described", "scale": "object scale", "position": "object position", "sun": "sun",
            "clock": "clock"}.get(kind, str(kind))


def _receiver(draw: dict) -> str:
    return {"plane": "ground", "bank": "range image (bank)", "steps": "mesh (steps)",
            "wall": "mesh (wall)"}[draw["receiver_shape"]]


#: factor name -> (how to bin a draw, the bins in table order)
FACTORS: dict[str, tuple[Callable[[dict], str], tuple[str, ...]]] = {
    "sun elevation (deg)": (lambda d: _edges_bin(d["sun_elevation_deg"], (8, 20, 35, 50, 65, 85), lambda v: f"{v:g}"),
                            ("8-20", "20-35", "35-50", "50-65", "65-85")),
    "image size (megapixels)": (lambda d: _edges_bin(_mp(d), (0.08, 0.3, 1.0, 3.0, 12.0), lambda v: f"{v:g}"),
                                ("0.08-0.3", "0.3-1", "1-3", "3-12")),
    "photos per group": (lambda d: {1: "1", 2: "2", 3: "3-4", 4: "3-4"}.get(len(d["photo_draws"]), "5-6"),
                         ("1", "2", "3-4", "5-6")),
    "k": (lambda d: _edges_bin(d["range_k"], (0.002, 0.004, 0.008, 0.015, 0.03), lambda v: f"{v:g}"),
          ("0.002-0.004", "0.004-0.008", "0.008-0.015", "0.015-0.03")),
    "rho": (lambda d: _edges_bin(d["rho"], (0.03, 0.08, 0.2, 0.45, 0.9), lambda v: f"{v:g}"),
            ("0.03-0.08", "0.08-0.2", "0.2-0.45", "0.45-0.9")),
    "mesh": (lambda d: d["mesh"], ("pillar", "ball", "knot", "dragon")),
    "receiver": (_receiver, ("ground", "range image (bank)", "mesh (steps)", "mesh (wall)")),
    "sun source": (lambda d: d["sun_source"], ("time+site", "given", "fitted")),
    "misdescription": (_misdescribed, ("well described", "object scale", "object position", "sun", "clock",
                                       "forced level of detail")),
}


def factor_bin(draw: dict, factor: str) -> str:
    return FACTORS[factor][0](draw)


def _share(num: int, den: int) -> float | None:
    return round(num / den, 4) if den else None


def summarize(records: Iterable[dict]) -> dict:
    """Counts and shares of a set of records: groups, reliable, flagged, k and rho covered among
    the reliable, confident misses (among all), the well described that are flagged and the false
    alarms among them."""
    records = list(records)
    js = [judge(r) for r in records]
    reliable = [j for j in js if j.reliable]
    well = [j for j in js if j.well_described]
    out = {
        "groups": len(js),
        "fitted": sum(j.fitted for j in js),
        "reliable": len(reliable),
        "flagged": sum(j.flagged for j in js),
        "k_covered": sum(bool(j.k_covered) for j in reliable),
        "rho_covered": sum(bool(j.rho_covered) for j in reliable),
        "k_bounds": sum(not j.identifiable for j in reliable),
        "confident_misses": sum(j.confident_miss for j in js),
        "well_described": len(well),
        "well_described_flagged": sum(j.flagged for j in well),
        "false_alarms": sum(j.flagged and bool(j.values_covered) for j in well),
    }
    out.update({
        "k_coverage": _share(out["k_covered"], out["reliable"]),
        "rho_coverage": _share(out["rho_covered"], out["reliable"]),
        "flagged_share": _share(out["flagged"], out["groups"]),
        "confident_miss_share": _share(out["confident_misses"], out["groups"]),
        "false_alarm_rate": _share(out["false_alarms"], out["well_described"]),
        "well_described_flagged_share": _share(out["well_described_flagged"], out["well_described"]),
    })
    return out


def bin_table(records: Iterable[dict], factor: str) -> list[dict]:
    """summarize() per bin of ``factor`` (bins in the factor's order, empty ones kept)."""
    records = list(records)
    how, bins = FACTORS[factor]
    by = {b: [] for b in bins}
    for r in records:
        by.setdefault(how(r["draw"]), []).append(r)
    return [{"bin": b, **summarize(rs)} for b, rs in by.items()]


def criteria(records: Iterable[dict]) -> dict:
    """Issue 24's targets against the records: coverage >= 90 % for k and rho in every bin with
    >= 20 reliable groups (and overall), confident misses <= 1 % of all groups, false alarms on
    well-described groups <= 5 %. Lists the bins that fail."""
    records = list(records)
    total = summarize(records)
    failing = []
    for factor in FACTORS:
        for row in bin_table(records, factor):
            if row["reliable"] < MIN_RELIABLE_PER_BIN:
                continue
            for what in ("k", "rho"):
                cov = row[f"{what}_coverage"]
                if cov is not None and cov < COVERAGE_TARGET:
                    failing.append({"factor": factor, "bin": row["bin"], "what": what, "coverage": cov,
                                    "reliable": row["reliable"]})
    for what in ("k", "rho"):
        cov = total[f"{what}_coverage"]
        if cov is not None and cov < COVERAGE_TARGET and total["reliable"] >= MIN_RELIABLE_PER_BIN:
            failing.append({"factor": "all", "bin": "all", "what": what, "coverage": cov,
                            "reliable": total["reliable"]})
    misses_ok = (total["confident_miss_share"] or 0.0) <= MAX_CONFIDENT_MISSES
    alarms_ok = (total["false_alarm_rate"] or 0.0) <= MAX_FALSE_ALARMS
    judged = ([{"factor": "all", "bin": "all"}] if total["reliable"] >= MIN_RELIABLE_PER_BIN else []) + [
        {"factor": factor, "bin": row["bin"]} for factor in FACTORS for row in bin_table(records, factor)
        if row["reliable"] >= MIN_RELIABLE_PER_BIN]
    size_ok = total["groups"] >= MIN_GROUPS
    return {"coverage_bins_failing": failing, "coverage_ok": not failing, "coverage_bins_judged": judged,
            "confident_misses_ok": misses_ok, "false_alarms_ok": alarms_ok, "size_ok": size_ok,
            "met": not failing and misses_ok and alarms_ok and size_ok}
