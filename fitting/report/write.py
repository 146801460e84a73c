"""Files written from a fit: results.json, the paper's Table 2 (Markdown and CSV), plots.

``write_report`` writes everything ``softshadow fit PHOTO_DIR --out OUT_DIR`` puts in
OUT_DIR (docs/formats.md, "softshadow fit writes"); ``format_table`` gives the same
table as plain text for the terminal. Every file is written atomically (a temporary
file in the same folder, then ``os.replace``), so an interruption leaves either the
old file or the new one, never half of one.

Units: ``range`` = 100 k and ``brightness`` = 255 rho^(1/2.2) (the paper's), next
to the physical k and rho; uncertainties are one sigma, propagated to paper units
to first order (d range = 100 dk, d brightness = 255/2.2 rho^(1/2.2 - 1) d rho).
"""

from __future__ import annotations

import csv
import dataclasses
import io
import json
import logging
import math
import os
from pathlib import Path
from collections.abc import Sequence

import numpy as np

from softshadow import brightness_to_paper, range_to_paper

from .comparison import (PAPER_TABLE2, PAPER_TIME_TOLERANCE_MIN, brightness_stderr, finite_or_none,
                         groups_in_time_order,
                         nearest_paper_time, range_stderr_paper, reference_for_group, truth_for_group)
from .files import atomic_writer, software_versions
from .results import FitResults, GroupResult

__all__ = [
    "PAPER_TABLE2", "PAPER_TIME_TOLERANCE_MIN", "software_versions", "nearest_paper_time",
    "reference_for_group", "brightness_stderr", "range_stderr_paper", "TableCell",
    "write_results_json", "write_table2", "format_table", "write_report",
    "REPORT_FILES", "clear_report",
]

logger = logging.getLogger(__name__)

UPPER_BOUND = "≤"
MISSING = "—"
RANGE_NAME = "Range of the soft shadow"
BRIGHTNESS_NAME = "Brightness of the shadow"

#: The files of a finished report in OUT_DIR (besides plots/*.png and *.svg).
REPORT_FILES = ("results.json", "table2.md", "table2.csv", "index.html")


def clear_report(out_dir) -> None:
    """Remove a previous run's report (REPORT_FILES and the plots' PNG and SVG files) from OUT_DIR, so that a
    refit that stops half-way never leaves old results beside new groups."""
    out_dir = Path(out_dir)
    for name in REPORT_FILES:
        (out_dir / name).unlink(missing_ok=True)
    plots = out_dir / "plots"
    if plots.is_dir():
        for f in [*plots.glob("*.png"), *plots.glob("*.svg")]:
            f.unlink(missing_ok=True)


def _json_default(obj):
    """numpy scalars/arrays and paths in ``skipped`` or ``software`` -> JSON types."""
    if isinstance(obj, np.generic):
        return obj.item()
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    if isinstance(obj, os.PathLike):
        return os.fspath(obj)
    raise TypeError(f"not JSON serialisable in results.json: {type(obj).__name__}")


def results_document(results: FitResults) -> dict:
    """The results.json document: groups (GroupResult.to_json), skipped, software
    (``software_versions()`` when the results carry none)."""
    doc = results.to_json()
    if not doc["software"]:
        doc["software"] = software_versions()
    return doc


def write_results_json(results: FitResults, out_dir) -> Path:
    """Write OUT_DIR/results.json (docs/formats.md) atomically; returns its path.

    Non-finite numbers are already None in ``GroupResult.to_json``; ``allow_nan=False``
    makes any that slip through (say in ``skipped``) an error instead of invalid JSON.
    """
    path = Path(out_dir) / "results.json"
    doc = results_document(results)
    with atomic_writer(path) as fh:
        json.dump(doc, fh, indent=2, ensure_ascii=False, allow_nan=False, default=_json_default)
        fh.write("\n")
    return path


# --------------------------------------------------------------------------- table model

@dataclasses.dataclass
class TableCell:
    """One value of the table: value (None = missing), stderr (one sigma, same units),
    upper_bound (the value is only an upper bound), notes (footnote texts)."""

    value: float | str | None
    stderr: float | None = None
    upper_bound: bool = False
    notes: list[str] = dataclasses.field(default_factory=list)


_UPPER_NOTE = ("upper bound (identifiable: false): the data do not constrain the range "
               "(e.g. a penumbra narrower than a pixel); the true range is at most this value")


def _group_notes(g: GroupResult) -> list[str]:
    """Footnotes that apply to the whole column."""
    notes = []
    if g.error is not None:
        notes.append(f"{g.label}: not fitted: {g.error}")
    elif g.fitted and not g.converged:
        notes.append(f"{g.label}: the solver did not converge; values are its last iterate")
    if g.error is None and (g.warnings or not g.reliable):
        head = "NOT RELIABLE" if not g.reliable else "warning"
        notes.append(f"{g.label}: {head}: " + ("; ".join(g.warnings) or "a consistency check failed"))
    if g.error is None and g.lod_faces and g.mesh_faces and g.lod_faces < g.mesh_faces:
        notes.append(f"{g.label}: fitted with a level of detail of {g.lod_faces:,} of the mesh's "
                     f"{g.mesh_faces:,} faces (--lod)")
    return notes


def _no_range_note(g: GroupResult) -> str:
    text = f"{g.label}: no scene geometry, so no range; "
    if finite_or_none(g.penumbra_px) is None:
        return text + "no penumbra width measured"
    text += f"penumbra width {_fmt(g.penumbra_px, 3)} px"
    if finite_or_none(g.penumbra_px_iqr) is not None:
        text += f" (IQR {_fmt(g.penumbra_px_iqr, 3)} px)"
    if finite_or_none(g.penumbra_m) is not None:
        text += f", {_fmt(g.penumbra_m, 3)} m"
    return text + " along the shadow edges"


def _table_rows(groups: Sequence[GroupResult], reference, truth
                ) -> tuple[list[tuple[str, str, list[TableCell]]], list[list[str]]]:
    """Rows (name, csv key, one cell per group) and per-column notes."""
    rows: list[tuple[str, str, list[TableCell]]] = []
    column_notes = [_group_notes(g) for g in groups]

    def cells(fn) -> list[TableCell]:
        return [fn(g) if g.error is None else TableCell(None) for g in groups]

    def range_cell(g: GroupResult) -> TableCell:
        if g.range_k is None:
            return TableCell(None, notes=[_no_range_note(g)])
        bound = not g.identifiable
        return TableCell(g.range, range_stderr_paper(g), bound, [_UPPER_NOTE] if bound else [])

    def k_cell(g: GroupResult) -> TableCell:
        if g.range_k is None:
            return TableCell(None)
        bound = not g.identifiable
        return TableCell(g.range_k, finite_or_none(g.range_stderr), bound, [_UPPER_NOTE] if bound else [])

    rows.append((RANGE_NAME + " (100 k)", "range", cells(range_cell)))
    rows.append((BRIGHTNESS_NAME + " (255 ρ^(1/2.2))", "brightness",
                 cells(lambda g: TableCell(g.brightness, brightness_stderr(g.rho, g.rho_stderr)))))
    rows.append(("k (physical range)", "range_k", cells(k_cell)))
    rows.append(("ρ (physical brightness)", "rho",
                 cells(lambda g: TableCell(finite_or_none(g.rho), finite_or_none(g.rho_stderr)))))
    if any(finite_or_none(g.penumbra_px) is not None for g in groups):
        rows.append(("Penumbra width (px, median; ± is the IQR)", "penumbra_px",
                     cells(lambda g: TableCell(finite_or_none(g.penumbra_px), finite_or_none(g.penumbra_px_iqr)))))

    if reference:
        refs = [reference_for_group(g, reference) for g in groups]
        if any(r is not None for r in refs):
            rows.append(("Paper, set by hand: range (its own units)", "reference_range",
                         [TableCell(None if r is None else float(r[0])) for r in refs]))
            rows.append(("Paper, set by hand: brightness", "reference_brightness",
                         [TableCell(None if r is None else float(r[1])) for r in refs]))
    if truth:
        truths = [truth_for_group(g, truth) for g in groups]
        if any(t is not None for t in truths):
            def truth_value(t, key):
                return None if t is None else finite_or_none(t.get(key))

            ks = [truth_value(t, "range_k") for t in truths]
            rhos = [truth_value(t, "rho") for t in truths]
            rows.append(("Truth: range", "truth_range",
                         [TableCell(None if k is None else float(range_to_paper(k))) for k in ks]))
            rows.append(("Truth: brightness", "truth_brightness",
                         [TableCell(None if r is None else float(brightness_to_paper(max(r, 0.0))))
                          for r in rhos]))
            rows.append(("Truth: k", "truth_range_k", [TableCell(k) for k in ks]))
            rows.append(("Truth: ρ", "truth_rho", [TableCell(r) for r in rhos]))
    return rows, column_notes


# --------------------------------------------------------------------------- formatting

# Digits shown without an uncertainty, per row (decimals for paper units, significant
# digits for the physical ones).
_DEFAULT_DECIMALS = {"range": 2, "brightness": 1, "reference_range": 1,
                     "reference_brightness": 1, "truth_range": 2, "truth_brightness": 1,
                     "penumbra_px": 2}
_DEFAULT_SIGNIFICANT = {"range_k": 3, "rho": 3, "truth_range_k": 3, "truth_rho": 3}


def _fmt(x: float, significant: int) -> str:
    """``x`` to ``significant`` significant digits, without exponent for ordinary sizes."""
    x = float(x)
    if x == 0.0 or not math.isfinite(x):
        return f"{x:g}"
    decimals = max(0, significant - 1 - math.floor(math.log10(abs(x))))
    return f"{x:.{min(decimals, 12)}f}"


def _format_value(value: float, stderr: float | None, key: str) -> str:
    """Value ± stderr with the uncertainty to two significant digits and the value to
    the same decimal place; without an uncertainty, the row's default precision."""
    s = finite_or_none(stderr)
    if s is not None and s > 0.0:
        decimals = min(12, max(0, 1 - math.floor(math.log10(s))))
        return f"{value:.{decimals}f} ± {s:.{decimals}f}"
    if key in _DEFAULT_SIGNIFICANT:
        return _fmt(value, _DEFAULT_SIGNIFICANT[key])
    return f"{value:.{_DEFAULT_DECIMALS.get(key, 3)}f}"


class _Footnotes:
    """Numbered footnotes, each text numbered once however many cells cite it."""

    def __init__(self) -> None:
        self.texts: list[str] = []

    def mark(self, texts: Sequence[str]) -> str:
        marks = []
        for t in texts:
            if t not in self.texts:
                self.texts.append(t)
            marks.append(f"[{self.texts.index(t) + 1}]")
        return "".join(marks)


def _cell_text(cell: TableCell, key: str, notes: _Footnotes, extra_notes: Sequence[str] = ()) -> str:
    all_notes = list(cell.notes) + list(extra_notes)
    if cell.value is None:
        text = MISSING
    elif cell.upper_bound:
        text = f"{UPPER_BOUND} {_format_value(float(cell.value), None, key)}"
    else:
        text = _format_value(float(cell.value), cell.stderr, key)
    marks = notes.mark(all_notes)
    return f"{text} {marks}" if marks else text


def _rendered(results: FitResults, reference, truth):
    """Header, text rows and footnotes shared by the Markdown and terminal tables."""
    groups = groups_in_time_order(results.groups)
    rows, column_notes = _table_rows(groups, reference, truth)
    notes = _Footnotes()
    header = ["Time of day"] + [g.label for g in groups]
    text_rows = []
    for r, (name, key, cells) in enumerate(rows):
        # Column-wide notes (failure, no convergence) ride on the first row only.
        text_rows.append([name] + [_cell_text(c, key, notes, col if r == 0 else ())
                                   for c, col in zip(cells, column_notes)])
    return header, text_rows, notes.texts


def _md_escape(text: str) -> str:
    return text.replace("|", "\\|")


def table2_markdown(results: FitResults, reference=None, truth=None) -> str:
    """The paper's Table 2 as Markdown: one column per time of day, then footnotes."""
    header, rows, notes = _rendered(results, reference, truth)
    lines = ["# Table 2: parameters of the soft shadow by time of day", ""]
    if not results.groups:
        lines.append("No groups were fitted.")
    else:
        lines.append("| " + " | ".join(_md_escape(h) for h in header) + " |")
        lines.append("|" + "|".join(["---"] + ["---:"] * (len(header) - 1)) + "|")
        lines += ["| " + " | ".join(_md_escape(c) for c in row) + " |" for row in rows]
    lines += ["", "Range = 100 k and brightness = 255 ρ^(1/2.2) are the paper's units "
              "(lit = 255); k and ρ are the physical values. ± is one standard error, "
              "propagated to first order; " f"{UPPER_BOUND} marks an upper bound, "
              f"{MISSING} a value that could not be measured."]
    if reference:
        lines.append("The paper's values (its Table 2) were set by hand from photos with its own expansion "
                     "rule, so its range is not on the scale of a measured 100 k; they are matched to a column "
                     f"by its label or by the nearest time of day within {PAPER_TIME_TOLERANCE_MIN:.0f} minutes.")
    if notes:
        lines += ["", "Notes:", ""] + [f"{i}. {_md_escape(t)}" for i, t in enumerate(notes, 1)]
    if results.skipped:
        lines += ["", "Skipped photos:", ""]
        lines += [f"- {_md_escape(str(s.get('photo', '?')))}: {_md_escape(str(s.get('reason', '')))}"
                  for s in results.skipped]
    return "\n".join(lines) + "\n"


def format_table(results: FitResults, reference=None, truth=None) -> str:
    """The same table as plain text for a terminal (fitted values beside the truth and
    the reference values when given), footnotes below."""
    if not results.groups:
        return "No groups were fitted.\n"
    header, rows, notes = _rendered(results, reference, truth)
    table = [header] + rows
    widths = [max(len(r[i]) for r in table) for i in range(len(header))]

    def line(cells):
        first = cells[0].ljust(widths[0])
        return "  ".join([first] + [c.rjust(w) for c, w in zip(cells[1:], widths[1:])]).rstrip()

    out = [line(header), "  ".join("-" * w for w in widths)] + [line(r) for r in rows]
    out += [f"[{i}] {t}" for i, t in enumerate(notes, 1)]
    out += [f"skipped {s.get('photo', '?')}: {s.get('reason', '')}" for s in results.skipped]
    return "\n".join(out) + "\n"


def table2_csv(results: FitResults, reference=None, truth=None) -> str:
    """The table as CSV: one row per quantity (column ``quantity``), per group a value
    column (the label) and a ``<label> stderr`` column. Numbers at full precision
    (``repr``), empty cells for missing values; extra rows: time, upper-bound flags,
    converged, error."""
    groups = groups_in_time_order(results.groups)
    rows, _ = _table_rows(groups, reference, truth)
    header = ["quantity"]
    for g in groups:
        header += [g.label, f"{g.label} stderr"]

    def num(x) -> str:
        x = finite_or_none(x) if not isinstance(x, str) else x
        return "" if x is None else (x if isinstance(x, str) else repr(float(x)))

    out = [header, ["time"] + sum(([g.time or "", ""] for g in groups), [])]
    for _, key, cells in rows:
        out.append([key] + sum(([num(c.value), num(c.stderr)] for c in cells), []))
        if key in ("range", "range_k"):
            # A machine-readable counterpart of the ≤ mark.
            out.append([f"{key}_is_upper_bound"] + sum(
                ([("true" if c.upper_bound else "false") if c.value is not None else "", ""]
                 for c in cells), []))
    out.append(["converged"] + sum(([("true" if g.converged else "false") if g.error is None else "", ""]
                                    for g in groups), []))
    out.append(["reliable"] + sum(([("true" if g.reliable else "false") if g.error is None else "", ""]
                                   for g in groups), []))
    out.append(["error"] + sum(([g.error or "", ""] for g in groups), []))
    buf = io.StringIO()
    csv.writer(buf, lineterminator="\n").writerows(out)
    return buf.getvalue()


def write_table2(results: FitResults, out_dir, reference=None, truth=None) -> tuple[Path, Path]:
    """Write OUT_DIR/table2.md and OUT_DIR/table2.csv (atomically); returns both paths.

    reference: {label or 'HH:MM': (range, brightness)} in paper units, e.g. PAPER_TABLE2,
    matched to a group by label or nearest time within 30 minutes; truth: a truth.json dict.
    """
    out_dir = Path(out_dir)
    md_path, csv_path = out_dir / "table2.md", out_dir / "table2.csv"
    with atomic_writer(md_path) as fh:
        fh.write(table2_markdown(results, reference, truth))
    with atomic_writer(csv_path, newline="") as fh:
        fh.write(table2_csv(results, reference, truth))
    return md_path, csv_path


# --------------------------------------------------------------------------- everything

def write_report(results: FitResults, out_dir, *, reference=None, truth=None,
                 plots: bool = True, group_plots: list[Path] | None = None) -> dict[str, Path]:
    """Write results.json, table2.md/.csv, (unless ``plots`` is False) the plots, and index.html (the
    page that shows them all) into OUT_DIR.

    group_plots: the groups' plots when they were already written (``plot_group_safely``
    while the fit went on); then only the range-against-time plot is drawn here.
    Returns {path relative to OUT_DIR (posix): absolute Path} of every file written.
    results.json and the tables come first; a plot that fails is logged and left out,
    never losing the numbers.
    """
    out_dir = Path(out_dir)
    written: list[Path] = [write_results_json(results, out_dir)]
    written += write_table2(results, out_dir, reference, truth)
    if plots:
        written += _write_plots(results, out_dir, reference, truth, group_plots)
    from .page import write_index_html
    try:
        written.append(write_index_html(results_document(results), out_dir))
    except Exception as exc:  # the page must never cost the results
        logger.warning("index.html skipped: %s: %s", type(exc).__name__, exc)
    return {p.relative_to(out_dir).as_posix(): p for p in written}


def plot_group_safely(group: GroupResult, out_dir) -> list[Path]:
    """``plots.plot_group``, logging instead of raising: a plot must never cost the results."""
    from . import plots  # matplotlib is only imported when plots are wanted
    try:
        return plots.plot_group(group, Path(out_dir))
    except Exception as exc:
        logger.warning("plots of group %s skipped: %s: %s", group.label, type(exc).__name__, exc)
        return []


def _write_plots(results: FitResults, out_dir: Path, reference, truth,
                 group_plots: list[Path] | None = None) -> list[Path]:
    from . import plots

    if group_plots is None:
        written = [p for g in results.groups for p in plot_group_safely(g, out_dir)]
    else:
        written = list(group_plots)
    try:
        p = plots.plot_range_vs_time(results, out_dir, reference=reference, truth=truth)
        if p is not None:
            written.append(p)
    except Exception as exc:
        logger.warning("range_vs_time plot skipped: %s: %s", type(exc).__name__, exc)
    return written
