"""One page per fit: ``OUT_DIR/index.html``, made from results.json's document and the plots beside it.

The page holds the table of values (paper and physical units, one-sigma errors, upper bounds), each
group's verdict (reliable, identifiable) and warnings, the photos left out and why, the range against
time of day, and each group's profile plot and overlays (the fitted shadow over the photo, in the
photo's own pixels). It reads only the JSON document and the plot files' names, so it can be
rebuilt from a finished OUT_DIR (``write_index_html(json.load(...), out_dir)``). No scripts, no
external files: it opens from disk in any browser.
"""

from __future__ import annotations

import html
from pathlib import Path
from collections.abc import Mapping, Sequence

from .files import atomic_writer, safe_name

__all__ = ["write_index_html"]

_STYLE = """
body { font-family: system-ui, sans-serif; margin: 2em auto; max-width: 1100px; padding: 0 1em; color: #222; }
h1 { font-size: 1.5em; } h2 { font-size: 1.2em; margin-top: 2em; border-bottom: 1px solid #ddd; }
table { border-collapse: collapse; margin: 1em 0; font-variant-numeric: tabular-nums; }
th, td { border: 1px solid #ccc; padding: 0.3em 0.6em; text-align: right; }
th { background: #f4f4f4; } td.text, th.text { text-align: left; }
.ok { color: #1a7f37; } .flag { color: #b35900; font-weight: 600; } .bad { color: #c62828; font-weight: 600; }
ul.warnings li { color: #b35900; } figure { margin: 1em 0; } figure img { max-width: 100%; border: 1px solid #ddd; }
figcaption { font-size: 0.9em; color: #555; } .small { font-size: 0.85em; color: #555; }
"""


def _fmt(value, stderr=None, digits: int = 3) -> str:
    if value is None:
        return "—"
    text = f"{value:.{digits}g}"
    return f"{text} ± {stderr:.2g}" if stderr is not None else text


def _verdict(group: Mapping) -> str:
    if group.get("error"):
        return '<span class="bad">not fitted</span>'
    if not group.get("reliable", False):
        return '<span class="flag">not reliable</span>'
    if not group.get("identifiable", False):
        return '<span class="flag">reliable; range is an upper bound</span>'
    return '<span class="ok">reliable</span>'


def _range_cell(group: Mapping) -> str:
    k = group.get("range_k")
    if k is None:
        return "—"
    if not group.get("identifiable", True):
        return f"≤ {group.get('range', 100 * k):.3g} (k ≤ {k:.3g})"
    err = group.get("range_stderr")
    return f"{_fmt(group.get('range'), None if err is None else 100 * err)} (k {_fmt(k, err)})"


def _brightness_cell(group: Mapping) -> str:
    rho = group.get("rho")
    if rho is None:
        return "—"
    return f"{_fmt(group.get('brightness'), None, 4)} (ρ {_fmt(rho, group.get('rho_stderr'))})"


def _table(groups: Sequence[Mapping]) -> str:
    head = ("<tr><th class='text'>group</th><th class='text'>time</th><th>photos</th>"
            "<th>range (100 k)</th><th>brightness (255 ρ<sup>1/2.2</sup>)</th><th>sun az / el (deg)</th>"
            "<th class='text'>verdict</th></tr>")
    rows = []
    for g in groups:
        az, el = g.get("sun_azimuth_deg"), g.get("sun_elevation_deg")
        sun = "—" if az is None or el is None else f"{az:.1f} / {el:.1f}"
        rows.append(f"<tr><td class='text'><a href='#{_anchor(g)}'>{html.escape(str(g.get('label')))}</a></td>"
                    f"<td class='text'>{html.escape(str(g.get('time') or '—'))}</td>"
                    f"<td>{len(g.get('photos') or [])}</td><td>{_range_cell(g)}</td>"
                    f"<td>{_brightness_cell(g)}</td><td>{sun}</td><td class='text'>{_verdict(g)}</td></tr>")
    return f"<table>{head}{''.join(rows)}</table>"


def _anchor(group: Mapping) -> str:
    return "group-" + safe_name(str(group.get("label")))


def _figure(path: Path, out_dir: Path, caption: str) -> str:
    rel = path.relative_to(out_dir).as_posix()
    vector = path.with_suffix(".svg")
    link = f" (<a href='{html.escape(vector.relative_to(out_dir).as_posix())}'>SVG</a>)" if vector.exists() else ""
    return (f"<figure><a href='{html.escape(rel)}'><img src='{html.escape(rel)}' alt='{html.escape(caption)}'"
            f" loading='lazy'></a><figcaption>{html.escape(caption)}{link}</figcaption></figure>")


def _group_section(group: Mapping, out_dir: Path) -> str:
    parts = [f"<h2 id='{_anchor(group)}'>{html.escape(str(group.get('label')))}</h2>",
             f"<p>{_verdict(group)}. Photos: {html.escape(', '.join(group.get('photos') or []))}.</p>"]
    if group.get("error"):
        parts.append(f"<p class='bad'>{html.escape(str(group['error']))}</p>")
    warnings = group.get("warnings") or []
    if warnings:
        parts.append("<ul class='warnings'>" + "".join(f"<li>{html.escape(w)}</li>" for w in warnings) + "</ul>")
    details = [("rmse", group.get("rmse")), ("profiles", group.get("n_profiles")),
               ("samples", group.get("n_samples")), ("penumbra (px)", group.get("penumbra_px")),
               ("blur (px)", group.get("blur_px")), ("profile", group.get("profile")),
               ("rule", group.get("rule")), ("rule criterion", group.get("rule_criterion")),
               ("sun from", group.get("sun_source")), ("mesh faces fitted", group.get("lod_faces")),
               ("seconds", group.get("seconds"))]
    shown = [f"{name} {_fmt(v) if isinstance(v, float) else html.escape(str(v))}"
             for name, v in details if v is not None]
    if shown:
        parts.append(f"<p class='small'>{'; '.join(shown)}.</p>")
    plots = out_dir / "plots"
    stem = safe_name(str(group.get("label")))
    profiles = plots / f"{stem}_profiles.png"
    if profiles.exists():
        parts.append(_figure(profiles, out_dir, "observed and fitted values across the shadow edge, per photo"))
    for overlay in sorted(plots.glob(f"{stem}_overlay_*.png")):
        photo = overlay.stem.split("_overlay_", 1)[1]
        parts.append(_figure(overlay, out_dir, f"{photo}: the fitted shadow over the photo (photo pixels)"))
    return "\n".join(parts)


def write_index_html(document: Mapping, out_dir, title: str | None = None) -> Path:
    """Write ``OUT_DIR/index.html`` from a results.json ``document`` and the plots in OUT_DIR/plots
    (those that exist); returns its path."""
    out_dir = Path(out_dir)
    groups = list(document.get("groups") or [])
    skipped = list(document.get("skipped") or [])
    software = document.get("software") or {}
    title = title or f"softshadow fit: {out_dir.resolve().name}"
    body = [f"<h1>{html.escape(title)}</h1>",
            "<p>Range k and brightness ρ of the soft shadow per time of day, with one-sigma errors "
            "(systematic part included). A range written ≤ is an upper bound: the photos do not resolve the "
            "penumbra. A group marked not reliable failed a consistency check: its values are given, its "
            "error bars are not to be trusted; its warnings say why.</p>",
            _table(groups)]
    if skipped:
        body.append("<h2>Photos left out</h2><ul>" + "".join(
            f"<li>{html.escape(str(s.get('photo')))}: {html.escape(str(s.get('reason')))}</li>" for s in skipped)
            + "</ul>")
    over_time = out_dir / "plots" / "range_vs_time.png"
    if over_time.exists():
        body.append("<h2>Over the day</h2>" + _figure(over_time, out_dir, "range and brightness against time of day"))
    body += [_group_section(g, out_dir) for g in groups]
    files = [name for name in ("results.json", "table2.md", "table2.csv") if (out_dir / name).exists()]
    body.append("<p class='small'>Files: " + ", ".join(f"<a href='{n}'>{n}</a>" for n in files)
                + ". Software: " + html.escape(", ".join(f"{k} {v}" for k, v in software.items() if v)) + ".</p>")
    page = ("<!DOCTYPE html>\n<html lang='en'><head><meta charset='utf-8'>"
            f"<title>{html.escape(title)}</title><style>{_STYLE}</style></head><body>\n"
            + "\n".join(body) + "\n</body></html>\n")
    path = out_dir / "index.html"
    with atomic_writer(path) as fh:
        fh.write(page)
    return path
