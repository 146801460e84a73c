"""docs/uncertainty_study.md: the calibration study's tables and plots, from its JSON alone."""

from __future__ import annotations

from pathlib import Path

from .coverage_tables import (COVERAGE_TARGET, FACTORS, MAX_CONFIDENT_MISSES, MAX_FALSE_ALARMS,
                              MIN_GROUPS, MIN_RELIABLE_PER_BIN, bin_table, criteria, judge, summarize)

__all__ = ["write_coverage_report", "coverage_plot", "pull_plot", "finding_text", "summary_section",
           "update_summary_section", "SECTION_BEGIN", "SECTION_END"]

COMMAND = ("nice -n 10 softshadow bench --what coverage --groups 300 --seed 0 --json docs/uncertainty_study.json "
           "--report docs/uncertainty_study.md")


def _pct(x) -> str:
    return "n/a" if x is None else f"{100 * x:.1f} %"


def _frac(num: int, den: int) -> str:
    return f"{num}/{den}" if den else "0/0"


def _where(failing: dict) -> str:
    return "all groups" if failing["factor"] == "all" else f"{failing['factor']} {failing['bin']}"


def _load(values) -> str:
    return "n/a" if not values else ", ".join(f"{v:g}" for v in values)


def _row(label: str, s: dict) -> str:
    return (f"| {label} | {s['groups']} | {s['reliable']} | {_frac(s['k_covered'], s['reliable'])} "
            f"({_pct(s['k_coverage'])}) | {_frac(s['rho_covered'], s['reliable'])} ({_pct(s['rho_coverage'])}) | "
            f"{s['k_bounds']} | {s['flagged']} ({_pct(s['flagged_share'])}) | {s['confident_misses']} | "
            f"{_frac(s['well_described_flagged'], s['well_described'])} ({s['false_alarms']}) |")


_HEAD = ("| bin | groups | reliable | k covered | rho covered | k bounds | flagged | confident misses | "
         "well described flagged (false alarms) |", "|---|---:|---:|---:|---:|---:|---:|---:|---:|")


def coverage_plot(records: list[dict], path: Path) -> None:
    """Coverage of k and rho (among reliable groups) per bin of each factor, bins with fewer than
    MIN_RELIABLE_PER_BIN reliable groups drawn pale."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    factors = list(FACTORS)
    cols = 3
    rows = (len(factors) + cols - 1) // cols
    fig, axes = plt.subplots(rows, cols, figsize=(4.2 * cols, 3.0 * rows), squeeze=False)
    for ax, factor in zip(axes.ravel(), factors):
        table = bin_table(records, factor)
        x = range(len(table))
        for off, what, colour in ((-0.2, "k", "tab:blue"), (0.2, "rho", "tab:orange")):
            vals = [(row[f"{what}_coverage"] or 0.0) for row in table]
            alpha = [1.0 if row["reliable"] >= MIN_RELIABLE_PER_BIN else 0.35 for row in table]
            for xi, v, a in zip(x, vals, alpha):
                ax.bar(xi + off, v, width=0.4, color=colour, alpha=a, label=what if xi == 0 else None)
        ax.axhline(COVERAGE_TARGET, color="k", lw=0.8, ls="--")
        ax.set_ylim(0.0, 1.02)
        ax.set_xticks(list(x))
        ax.set_xticklabels([f"{row['bin'].replace(' ', chr(10))}\n({row['reliable']})" for row in table],
                           fontsize=7, rotation=0)
        ax.set_title(factor, fontsize=9)
    for ax in axes.ravel()[len(factors):]:
        ax.axis("off")
    axes[0, 0].legend(fontsize=7, loc="lower left")
    fig.suptitle("Coverage within 2 stated sigma among reliable groups (reliable count in brackets; "
                 f"pale: fewer than {MIN_RELIABLE_PER_BIN}; dashed: {COVERAGE_TARGET:.0%})", fontsize=9)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)


def pull_plot(records: list[dict], path: Path) -> None:
    """Histograms of the pulls (value - truth) / stated sigma of the reliable groups (k: identifiable
    only), well-described and misdescribed stacked, with the unit normal scaled to the counts."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np
    js = [judge(r) for r in records]
    fig, axes = plt.subplots(1, 2, figsize=(9, 3.2))
    grid = np.linspace(-5, 5, 201)
    for ax, what in zip(axes, ("k", "rho")):
        def pulls_of(well):
            p = np.array([getattr(j, f"{what}_pull") for j in js if j.reliable and j.well_described == well
                          and getattr(j, f"{what}_pull") is not None], dtype=float)
            return p[np.isfinite(p)]
        good, bad = pulls_of(True), pulls_of(False)
        pulls = np.concatenate([good, bad])
        ax.hist([np.clip(good, -5.99, 5.99), np.clip(bad, -5.99, 5.99)], bins=np.linspace(-6, 6, 49), stacked=True,
                density=False, color=["tab:blue", "tab:red"], alpha=0.75,
                label=[f"well described ({len(good)})", f"misdescribed or forced LOD ({len(bad)})"])
        scale = max(len(pulls), 1) * 0.25  # the unit normal scaled to the counts (bins 0.25 wide)
        grid_y = scale * np.exp(-grid ** 2 / 2) / np.sqrt(2 * np.pi)
        ax.plot(grid, grid_y, "k-", lw=1, label="unit normal")
        for v in (-2, 2):
            ax.axvline(v, color="k", lw=0.6, ls="--")
        ax.set_xlabel(f"({what} - truth) / stated sigma (clipped at 6)")
        ax.set_ylabel("reliable groups")
        ax.set_title(f"{what}: median |pull| {np.median(np.abs(pulls)):.2f} (well described "
                     f"{np.median(np.abs(good)) if len(good) else float('nan'):.2f})", fontsize=9)
        ax.legend(fontsize=7)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)


def _draw_line(d: dict) -> str:
    bits = [f"{d['mesh']} x{d['object_scale']:.2f}", d["receiver_shape"], f"{d['width']}x{d['height']}",
            f"{len(d['photo_draws'])} photos", f"sun {d['sun_azimuth_deg']:.0f}/{d['sun_elevation_deg']:.1f} deg "
            f"({d['sun_source']})", f"k {d['range_k']:.4f}", f"rho {d['rho']:.3f}"]
    if d.get("misdescription") == "scale":
        bits.append(f"scale said x{d['scale_factor']:.3f}")
    elif d.get("misdescription") == "position":
        bits.append(f"position off {[round(100 * v, 1) for v in d['position_offset_m'][:2]]} cm")
    elif d.get("misdescription") == "sun":
        bits.append(f"sun off {[round(v, 2) for v in d['sun_offset_deg']]} deg (az, el)")
    elif d.get("misdescription") == "clock":
        bits.append(f"clock off {d['clock_offset_s'] / 60:+.1f} min")
    if d.get("fit_lod") is not None:
        bits.append(f"--lod {d['fit_lod']}")
    return ", ".join(bits)


def _case_rows(records: list[dict], pick) -> list[str]:
    out = []
    for r in records:
        j = judge(r)
        if not pick(j, r):
            continue
        res = r.get("result") or {}
        k = res.get("range_k")
        rho = res.get("rho")
        kk = "n/a" if k is None else f"{k:.5f} ± {res.get('range_stderr') or 0:.5f}{'' if j.identifiable else ' (bound)'}"
        rr = "n/a" if rho is None else f"{rho:.4f} ± {res.get('rho_stderr') or 0:.4f}"
        warn = "; ".join(res.get("warnings") or []) or res.get("error") or r.get("error") or ""
        out.append(f"| {r['index']} | {_draw_line(r['draw'])} | {kk} vs {r.get('k_true', float('nan')):.5f} | "
                   f"{rr} vs {r.get('rho_true', float('nan')):.4f} | {warn.replace('|', '/')} |")
    return out


def write_coverage_report(result: dict, md_path: Path, json_name: str | None = None) -> None:
    """The report (tables, two plots in img/ beside it) from the study's JSON ``result``."""
    md_path = Path(md_path)
    records = result["records"]
    env = result.get("environment") or {}
    m = env.get("machine") or {}
    total = summarize(records)
    crit = criteria(records)
    img_cov = md_path.parent / "img" / f"{md_path.stem}_coverage.png"
    img_pull = md_path.parent / "img" / f"{md_path.stem}_pulls.png"
    coverage_plot(records, img_cov)
    pull_plot(records, img_pull)
    times = sorted(r["finished_utc"] for r in records if r.get("finished_utc"))
    seconds = [r.get("seconds_synth", 0) + r.get("seconds_fit", 0) for r in records if "seconds_fit" in r]
    loads = [r["load_average"][0] for r in records if r.get("load_average")]
    L = ["# Calibration study: do the stated errors cover the truth?", "",
         f"Generated by `{env.get('command', COMMAND)}` (resumable: records in `ROOT/records.jsonl`; the report alone is remade with "
         f"`softshadow bench --what coverage --from-json docs/{json_name or 'uncertainty_study.json'} --report "
         f"docs/{md_path.name}`). Every figure below comes from "
         f"{'`' + json_name + '`' if json_name else 'that run'}'s records.", "",
         f"- Date: {env.get('date_utc', 'n/a')} (groups finished {times[0] if times else 'n/a'} to "
         f"{times[-1] if times else 'n/a'})",
         f"- Machine: {m.get('cpu', 'n/a')}, {m.get('cores', 'n/a')} cores, {m.get('memory_gb', 'n/a')} GB, "
         f"{m.get('platform', 'n/a')}; shared with other work, the study niced",
         f"- Load average (1 min) while groups finished: median {sorted(loads)[len(loads) // 2] if loads else 'n/a'}, "
         f"range {min(loads) if loads else 'n/a'}-{max(loads) if loads else 'n/a'}; at the start "
         f"{_load(m.get('load_average_1_5_15_min'))}",
         f"- Code: {result.get('commit') or 'n/a'}; seed {result.get('seed')}; {len(records)} groups; "
         f"render and fit took {sum(seconds) / 3600:.1f} hours of wall time in all, median "
         f"{sorted(seconds)[len(seconds) // 2] if seconds else 0:.0f} s a group",
         ""]
    L += ["## What is drawn", "",
          "Each group is drawn from `data_synth.draw.ScenePrior` (the study's prior adds the real dragon), "
          "rendered by `data_synth`'s physical renderer (ray-cast sun disk and sky, independent of the fitted "
          "model) into its own folder and fitted with the default options of `fitting.fit_folder` (plus the "
          "forced level of detail where drawn). Group i of seed S is `default_rng([S, i])`: "
          "`python -m benchmarks.coverage --seed S --index i --out DIR` re-makes its folder.", "",
          "- sun: elevation uniform 8-85 deg, azimuth uniform; a site and a day and time are solved for it, so "
          "the sun also follows from the time and the site (pvlib's SPA, as the fitter reads it);",
          "- light: k = tan(sun radius) log-uniform 0.002-0.03; rho log-uniform 0.03-0.9;",
          "- object: pillar, ball, knot (the procedural trefoil tube) or the real dragon (26,584 faces), "
          "scaled by a log-uniform 0.75-1.33, turned about z at random;",
          "- receiver: the ground (1/2), a bank rising along the shadow given as range images (1/4), or a mesh "
          "(steps or a wall, 1/4); where the shadow cannot reach the drawn receiver (a high sun's short shadow, "
          "a bank too steep for a low sun) the ground is used instead, so the bins are of the receiver rendered;",
          "- photos: 1-6 per group, 20-90 s apart; a pixel count log-uniform from 320x240 to 4000x3000 (4:3). "
          "Render cost is capped at 24 megapixels per group: a draw with more photos than that allows keeps "
          "24 MP / (its pixels) of them (a 4000x3000 group has one or two photos);",
          "- views: handheld across the shadow (35-145 deg off its direction) or facing the lit side of steps "
          "or a wall (40-75 deg off the sun's azimuth), a fifth of the photos on the ground top-down maps;",
          "- camera: optical blur 0.3-1.3 px per photo, 3,000-40,000 electrons at full scale (log-uniform) and "
          "2-10 e- read noise, vignetting 0-0.35, lit white at 0.45-0.85 of full scale, exposure differences "
          "between photos (log gain normal, sigma 0-0.25), JPEG quality 65-98 or (a tenth) 16-bit PNG;",
          "- ground: concrete or asphalt; a white sheet along the shadow on 70 % of the ground receivers;",
          "- sun source: time and site (45 %), given in scene.toml (30 %), fitted (25 %);",
          "- misdescription: 40 % of the groups well described; the others one error: object scale off by "
          "2-15 %, position by 1-5 cm, the given sun by 0.5-3 deg, the clock by 5-20 minutes (sun from time and "
          "site), or a forced level of detail of 1-25 % of the mesh's faces.", ""]
    L += ["## Definitions", ""] + [f"- **{k}**: {v}." for k, v in (result.get("definitions") or {}).items()] + [""]
    L += ["## Where it stands against the targets", "",
          _size_line(total, crit),
          f"- Coverage >= {COVERAGE_TARGET:.0%} for k and for rho in every bin with >= {MIN_RELIABLE_PER_BIN} "
          f"reliable groups: **{'met' if crit['coverage_ok'] else 'not met'}**"
          + ("" if crit.get("size_ok", True) or not crit["coverage_ok"] else " in the bins judged, at this size")
          + ("" if crit["coverage_ok"] else " (" + "; ".join(
              f"{_where(f)}: {f['what']} {_pct(f['coverage'])} of {f['reliable']}"
              for f in crit["coverage_bins_failing"]) + ")"),
          f"- Confident misses <= {MAX_CONFIDENT_MISSES:.0%} of all groups: "
          f"**{'met' if crit['confident_misses_ok'] else 'not met'}** ({total['confident_misses']} of "
          f"{total['groups']}, {_pct(total['confident_miss_share'])})",
          f"- False alarms on well-described groups <= {MAX_FALSE_ALARMS:.0%}: "
          f"**{'met' if crit['false_alarms_ok'] else 'not met'}** ({total['false_alarms']} of "
          f"{total['well_described']}, {_pct(total['false_alarm_rate'])}: flagged although k and rho were within "
          f"the stated errors). All flags on well-described groups, the right ones included: "
          f"{total['well_described_flagged']} ({_pct(total['well_described_flagged_share'])})", ""]
    L += ["## All groups", "", *_HEAD, _row("all", total),
          _row("well described", summarize([r for r in records if judge(r).well_described])),
          _row("misdescribed", summarize([r for r in records if not judge(r).well_described])), "",
          "k bounds: reliable groups whose k is not identifiable (covered when the truth is under the bound). "
          "The last column counts among the well-described groups of the row: those flagged, and in brackets the "
          "false alarms among them (flagged although k and rho were within the stated errors).", "",
          f"![coverage per bin](img/{img_cov.name})", "", f"![pulls](img/{img_pull.name})", ""]
    L += ["## Per factor", ""]
    for factor in FACTORS:
        L += [f"### {factor}", "", *_HEAD]
        L += [_row(row["bin"], row) for row in bin_table(records, factor)]
        L.append("")
    misses = _case_rows(records, lambda j, r: j.confident_miss)
    L += ["## Confident misses", "", "Reliable groups with k or rho beyond 3 stated sigma.", ""]
    if misses:
        L += ["| group | draw | k vs truth | rho vs truth | warnings |", "|---|---|---|---|---|", *misses, ""]
    else:
        L += ["None.", ""]
    alarms = _case_rows(records, lambda j, r: j.well_described and j.flagged)
    L += ["## Well-described groups flagged", "", "Well-described groups reported unreliable (or failed), with "
          "the warnings; those whose k and rho were within the stated errors anyway are the false alarms.", ""]
    if alarms:
        L += ["| group | draw | k vs truth | rho vs truth | warnings |", "|---|---|---|---|---|", *alarms, ""]
    else:
        L += ["None.", ""]
    uncovered = _case_rows(records, lambda j, r: j.reliable and not j.confident_miss
                           and not (j.k_covered and j.rho_covered))
    L += ["## Reliable groups outside 2 sigma (not confident misses)", ""]
    if uncovered:
        L += ["| group | draw | k vs truth | rho vs truth | warnings |", "|---|---|---|---|---|", *uncovered, ""]
    else:
        L += ["None.", ""]
    md_path.parent.mkdir(parents=True, exist_ok=True)
    md_path.write_text("\n".join(L) + "\n")
    # The summary in docs/uncertainty.md beside the report (when it has the study's markers).
    update_summary_section(md_path.parent / "uncertainty.md", result, md_path.name)


def finding_text(record: dict, kind: str, root: str | None = None) -> str:
    """A failure of one group written for the verdict's owner: the draw's parameters, what was
    reported, the truth, and the commands that re-make and refit its folder."""
    import json
    d = record["draw"]
    res = record.get("result") or {}
    j = judge(record)

    def pull(x):
        return "n/a" if x is None else f"{x:+.1f} sigma"
    keep = {k: res.get(k) for k in ("range_k", "range_stderr", "rho", "rho_stderr", "reliable", "identifiable",
                                     "penumbra_px", "blur_px", "lod_faces", "mesh_faces", "sun_azimuth_deg",
                                     "sun_elevation_deg", "sun_source", "n_profiles", "rmse", "error")}
    seed, index = record["seed"], record["index"]
    folder = f"/tmp/coverage-g{index}"
    lod = f" --lod {d['fit_lod']}" if d.get("fit_lod") is not None else ""
    lines = [f"### seed {seed} group {index}: {kind}", "",
             f"- draw: {_draw_line(d)}; blur {min(p['blur_px'] for p in d['photo_draws']):.2f}-"
             f"{max(p['blur_px'] for p in d['photo_draws']):.2f} px, {d['full_well_e']:.0f} e-, "
             f"{d['fmt']} q{d['jpeg_quality']}, {d['texture']}{' + paper' if d['paper'] else ''}, "
             f"exposure spread {d['exposure_spread']:.2f}, site {d['site']}, time {d['time']}",
             f"- reported: {json.dumps(keep)}",
             f"- warnings: {res.get('warnings') or []}; skipped: {record.get('skipped') or []}",
             f"- truth: k {record.get('k_true'):.5f}, rho {record.get('rho_true'):.4f}, sun "
             f"{record.get('sun_azimuth_true'):.2f}/{record.get('sun_elevation_true'):.2f} deg, geometric penumbra "
             f"{record.get('truth_penumbra_px') or float('nan'):.1f} px; pulls: k {pull(j.k_pull)}, rho {pull(j.rho_pull)}",
             f"- re-create: `cd <checkout> && PYTHONPATH=. python -m benchmarks.coverage --seed {seed} --index {index} "
             f"--out {folder} && softshadow fit {folder} --out {folder}/fit{lod}`"
             + (f" (the study's folder: `{record['folder']}`)" if record.get("folder") else ""), ""]
    return "\n".join(lines)


SECTION_BEGIN = "<!-- coverage-study: generated by softshadow bench --what coverage; edit benchmarks/coverage_report.py -->"
SECTION_END = "<!-- coverage-study: end -->"


def _size_line(total: dict, crit: dict) -> str:
    """The study's size against the issue's, and the bins the coverage target could be judged in."""
    judged = crit.get("coverage_bins_judged") or []
    where = ", ".join("all groups" if b["factor"] == "all" else f"{b['factor']} {b['bin']}" for b in judged)
    return (f"- Size: {total['groups']} groups, "
            + (f"**fewer than the {MIN_GROUPS} the issue asks for**: no target below is shown met at this size"
               if not crit.get("size_ok", True) else f"at least the {MIN_GROUPS} the issue asks for")
            + f". Bins holding >= {MIN_RELIABLE_PER_BIN} reliable groups, where coverage is judged: "
            + (where if where else "none") + ".")


def summary_section(result: dict, study_page: str = "uncertainty_study.md") -> str:
    """The study's summary for docs/uncertainty.md (between SECTION_BEGIN and SECTION_END)."""
    records = result["records"]
    env = result.get("environment") or {}
    m = env.get("machine") or {}
    total = summarize(records)
    crit = criteria(records)
    well = summarize([r for r in records if judge(r).well_described])
    wrong = summarize([r for r in records if not judge(r).well_described])
    loads = sorted(r["load_average"][0] for r in records if r.get("load_average"))
    L = [SECTION_BEGIN,
         f"## Calibration study (measured {env.get('date_utc', 'n/a')}, {m.get('cores', '?')}-core shared machine, "
         f"load {loads[0] if loads else 'n/a'}-{loads[-1] if loads else 'n/a'})", "",
         f"{total['groups']} groups drawn at random from a documented prior (sun elevation 8-85 deg at any "
         "azimuth, 320x240 to 4000x3000, 1-6 photos, k 0.002-0.03, rho 0.03-0.9, pillar, ball, knot and the real "
         "dragon, ground, range-image and mesh receivers, the sun from time and site, given or fitted, camera "
         "blur, noise, JPEG and exposures, and misdescribed scenes), rendered by `data_synth`'s physical "
         "renderer and fitted with the default options. The whole study, its prior, every group's draw, result "
         f"and truth, and the tables per factor bin: [{study_page}]({study_page}). Re-run it with "
         "`softshadow bench --what coverage --json docs/uncertainty_study.json --report docs/uncertainty_study.md` "
         "(hours of CPU; resumable).", "", *_HEAD, _row("all", total), _row("well described", well),
         _row("misdescribed", wrong), "",
         f"Code: {result.get('commit') or 'n/a'} (seed {result.get('seed')}); machine: {m.get('cpu', 'n/a')}, "
         f"{m.get('cores', '?')} cores, shared with other work (load average over 1 minute while the groups "
         f"finished: median {loads[len(loads) // 2] if loads else 'n/a'}).", "",
         _size_line(total, crit),
         f"- Coverage >= {COVERAGE_TARGET:.0%} for k and rho in every bin with >= {MIN_RELIABLE_PER_BIN} reliable "
         f"groups: {'met' if crit['coverage_ok'] else 'not met'}"
         + ("" if crit.get("size_ok", True) or not crit["coverage_ok"] else " in the bins judged, at this size")
         + ("" if crit["coverage_ok"] else " (" + "; ".join(
             f"{_where(f)}: {f['what']} {_pct(f['coverage'])}" for f in crit["coverage_bins_failing"])
            + ")") + ".",
         f"- Confident misses (reliable, beyond 3 stated sigma): {total['confident_misses']} of {total['groups']} "
         f"groups ({_pct(total['confident_miss_share'])}; target <= {MAX_CONFIDENT_MISSES:.0%}).",
         f"- False alarms (well-described groups flagged although k and rho were within the stated errors): "
         f"{total['false_alarms']} of {total['well_described']} ({_pct(total['false_alarm_rate'])}; target <= "
         f"{MAX_FALSE_ALARMS:.0%}). Well-described groups flagged, the right flags included: "
         f"{total['well_described_flagged']} ({_pct(total['well_described_flagged_share'])}).", "",
         "Coverage counts the groups reported reliable; a k that is not identifiable is covered when the truth "
         "lies under its bound.", SECTION_END]
    return "\n".join(L)


def update_summary_section(doc: Path, result: dict, study_page: str = "uncertainty_study.md") -> bool:
    """Replace the study's section of ``doc`` (between its markers); False when the doc has none."""
    doc = Path(doc)
    if not doc.exists():
        return False
    text = doc.read_text()
    a, b = text.find(SECTION_BEGIN), text.find(SECTION_END)
    if a < 0 or b < a:
        return False
    doc.write_text(text[:a] + summary_section(result, study_page) + text[b + len(SECTION_END):])
    return True
