"""The speed-against-error report: a Pareto plot (PNG) and ``docs/speed_vs_error.md``, made only
from the JSON a sweep wrote (no figure is typed in)."""

from __future__ import annotations

import json
from pathlib import Path

__all__ = ["image_cases", "pareto_front", "pareto_plot", "write_report", "report_from_json"]


def image_cases(result: dict) -> list[tuple[str, dict]]:
    """(label, case) of every timed render that has an image error."""
    out = []
    for key in ("pillar", "ball", "dragon", "knot"):
        if key in result:
            out.append((f"{key} {result[key]['pixels']} px", result[key]))
    for c in result.get("resolution", []):
        out.append((f"pillar {c['pixels']} px", c))
    for c in result.get("profile", []):
        out.append((f"pillar {c['profile']}", c))
    for c in result.get("dtype", []):
        out.append((f"pillar {c['dtype']}", c))
    for c in result.get("lod", []):
        out.append((f"dragon {c['faces']} faces", c))
    for name, row in result.get("paper", {}).get("table3", {}).items():
        out.append((f"paper {name} soft", row["soft"]))
        out.append((f"paper {name} hard", row["hard"]))
    return out


def pareto_front(points: list[tuple[float, float]]) -> list[int]:
    """Indices of the points (time, error) no other point beats in both, by increasing time."""
    order = sorted(range(len(points)), key=lambda i: (points[i][0], points[i][1]))
    front, best = [], float("inf")
    for i in order:
        if points[i][1] < best:
            front.append(i)
            best = points[i][1]
    return front


def pareto_plot(result: dict, path: Path) -> None:
    """Time against penumbra-band error of every image case (log-log), the Pareto front joined."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    cases = [(lab, c) for lab, c in image_cases(result) if c["error"].get("rms_band") is not None]
    fig, ax = plt.subplots(figsize=(7.5, 5))
    groups = {}
    for lab, c in cases:
        groups.setdefault(c.get("renderer", "softshadow"), []).append((lab, c))
    for renderer, items in groups.items():
        ax.scatter([c["median_ms"] for _, c in items], [c["error"]["rms_band"] for _, c in items],
                   label=renderer, s=22)
        for lab, c in items:
            ax.annotate(lab, (c["median_ms"], c["error"]["rms_band"]), fontsize=6, xytext=(3, 2),
                        textcoords="offset points")
    pts = [(c["median_ms"], c["error"]["rms_band"]) for _, c in cases]
    front = pareto_front(pts)
    ax.plot([pts[i][0] for i in front], [pts[i][1] for i in front], "k--", lw=0.8, label="Pareto front")
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("median wall time per render after compilation (ms)")
    ax.set_ylabel("RMS shading error in the penumbra band")
    ax.set_title("Speed against error (top-down ground map, real sun)")
    ax.legend(fontsize=8)
    ax.grid(True, which="both", lw=0.3)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=120)
    plt.close(fig)


def _f(x, fmt="{:.4f}"):
    return "n/a" if x is None else fmt.format(x)


def _case_table(rows: list[tuple[str, dict]]) -> list[str]:
    lines = ["| case | faces | pixels | profile | dtype | time (ms) | peak extra (MB) | RMS | RMS band | max abs |",
             "|---|---:|---:|---|---|---:|---:|---:|---:|---:|"]
    for lab, c in rows:
        e = c["error"]
        lines.append(f"| {lab} | {c.get('faces', '')} | {c.get('pixels', '')} | {c.get('profile', '')} | "
                     f"{c.get('dtype', '')} | {_f(c['median_ms'], '{:.1f}')} | {_f(c.get('peak_extra_mb'), '{:.0f}')} | "
                     f"{_f(e['rms'])} | {_f(e['rms_band'])} | {_f(e['max_abs'], '{:.3f}')} |")
    return lines


def _paper_sections(paper: dict) -> list[str]:
    L = ["## The Shoji paper's own algorithm (Table 3)", "",
         "The paper's section 3.2 as written (`softshadow_cli/bench/shoji.py`, NumPy/OpenCV): the "
         "expanded shadow volume counted in a stencil buffer, the shadow texture's states -1/1/2, the "
         "intensity rising along the shadow's direction across the bounding quadrilateral, the "
         "neighbourhood test P(i +- I, j +- I) at silhouette pixels, linear alpha between the two "
         "outlines and alpha blending. Hard: the stencil volume alone; soft: the whole algorithm, with its "
         "range and expansion fitted to the physical truth (grid search). Same maps, light and truth as "
         "above; the paper's times are on a Pentium 4 at 2.8 GHz.", "",
         "| mesh | faces | paper hard (ms) | paper soft (ms) | hard here (ms) | soft here (ms) | soft - hard here (ms) | "
         "range (px) | expansion | RMS band, hard | RMS band, soft | RMS band, vs this renderer |",
         "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|"]
    for name, r in paper.get("table3", {}).items():
        h, s, f = r["hard"], r["soft"], r["fitted_to_truth"]
        L.append(f"| {name} | {r['faces']} | {r['paper_hard_ms']:.0f} | {r['paper_soft_ms']:.0f} | "
                 f"{h['median_ms']:.1f} | {s['median_ms']:.1f} | {s['median_ms'] - h['median_ms']:.1f} | "
                 f"{f['range_px']:.0f} | {f['expand']:.3f} | {_f(h['error']['rms_band'])} | "
                 f"{_f(s['error']['rms_band'])} | {_f(r['soft_vs_softshadow']['rms_band'])} |")
    if paper.get("table2"):
        L += ["", "## Table 2 in the paper's own parameters", "",
              "The paper's \"range of the soft shadow\" is the increment of its soft-shadow intensity: the "
              "intensity rises from 0 next to the object to `range` at the far end of the shadow's bounding "
              "quadrilateral, and a silhouette pixel of intensity I makes its (2I+1) x (2I+1) neighbourhood "
              "soft. So `range` is the soft band's width in shadow-texture pixels at the shadow's far end: a "
              "screen-space number, inversely proportional to the pixel size, not 100 k. The model's linear "
              "penumbra at the tip of a pillar of height h is 2 k h / sin^2(E) long on the ground, so a band "
              "that matched it would have range = 2 k h / (sin^2(E) * pixel size), with the linear-ramp k "
              "(about 0.854 tan r for a sun disk of radius r): the column \"range from true k\". The fit "
              "reads a fraction c of that (the last column): its expansion moves the outline outwards and "
              "takes part of the width, and its band is a square neighbourhood. So at a given resolution "
              "**range = c * 2 k h / (sin^2(E) * pixel size)** with c as measured below.", "",
              "Below, the table2 preset's three lights (the same sun positions, disk radii and rho as its "
              "photos) rendered top-down by the physical ray caster over each shadow's square, then fitted "
              "with the paper's algorithm (range, expansion, rho; grid search):", "",
              "| time | sun elev. (deg) | pixel (mm) | true k | true rho | paper range | fitted range (px) | "
              "range from true k (px) | fitted expansion | paper brightness | fitted brightness | true brightness | c = fitted / from k |",
              "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|"]
        for r in paper["table2"]:
            L.append(f"| {r['label']} | {r['sun_elevation_deg']:.1f} | {1000 * r['pixel_m']:.1f} | "
                     f"{r['truth_range_k']:.5f} | {r['truth_rho']:.3f} | {_f(r['paper_range'], '{:.0f}')} | "
                     f"{r['fitted_range_px']:.0f} | {r['predicted_range_px']:.1f} | {r['fitted_expand']:.3f} | "
                     f"{_f(r['paper_brightness'], '{:.0f}')} | {r['fitted_brightness']:.1f} | {r['truth_brightness']:.1f} | "
                     f"{r['fitted_range_px'] / r['predicted_range_px']:.2f} |")
    return L


def _table1_section(rows: list[dict]) -> list[str]:
    d = rows[0]["diameter_m"]
    L = ["## Table 1: expansion ratio S/H", "",
         f"A sphere {1000 * d:.0f} mm across held 0.3, 1.5 and 3 m from the ground along the light (sun "
         "elevation 60 deg, the real sun's disk), rendered top-down by the physical ray caster. Measured: "
         "across the light through the shadow's centre, S where any of the sun's disk is hidden (visible "
         "fraction < 0.98), H where all of it is (< 0.02). Predicted: k fitted to the same map with this "
         "renderer (linear profile), S/H = (D + 2 k d) / (D - 2 k d). The ratio depends on the object's "
         "size, which the paper does not give; at this size it lands near the paper's.", "",
         "| distance (m) | pixel (mm) | measured S (mm) | measured H (mm) | measured S/H (%) | fitted k | "
         "true tan r | predicted S/H (%) | paper S/H (%) |", "|---:|---:|---:|---:|---:|---:|---:|---:|---:|"]
    for r in rows:
        L.append(f"| {r['distance_m']} | {1000 * r['pixel_m']:.2f} | {1000 * r['measured_S_m']:.1f} | "
                 f"{1000 * r['measured_H_m']:.1f} | {_f(r['measured_ratio_percent'], '{:.1f}')} | "
                 f"{r['fitted_k']:.5f} | {r['truth_k']:.5f} | {r['predicted_ratio_percent']:.1f} | "
                 f"{_f(r['paper_ratio_percent'], '{:.0f}')} |")
    return L


def scaling_plot(scaling: dict, path: Path) -> None:
    """Time against faces and against pixels (log-log) for the three renderers."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, axes = plt.subplots(1, 2, figsize=(10, 4.2))
    for r, style in (("softshadow", "o-"), ("paper", "s-"), ("naive", "^-")):
        rows = [x for x in scaling["by_faces"] if "median_ms" in x[r]]
        axes[0].plot([x["faces"] for x in rows], [x[r]["median_ms"] for x in rows], style, label=r)
        for name, ls in (("pillar", "-"), ("dragon", "--")):
            rows = [x for x in scaling["by_pixels"] if x["case"].startswith(name) and "median_ms" in x[r]]
            axes[1].plot([x["pixels"] for x in rows], [x[r]["median_ms"] for x in rows], style[0] + ls,
                         label=f"{r}, {name}")
    axes[0].set_xlabel(f"faces ({scaling['pixels_for_faces']}^2 px map)")
    axes[1].set_xlabel("pixels")
    for ax in axes:
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_ylabel("median ms")
        ax.grid(True, which="both", lw=0.3)
        ax.legend(fontsize=7)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=120)
    plt.close(fig)


def _scaling_section(scaling: dict) -> list[str]:
    sf = scaling["slope_vs_faces"]
    L = ["## Scaling", "",
         "Time against faces and against pixels for this renderer, the paper's algorithm and the naive "
         "renderer (every pixel against every silhouette edge, NumPy; the same linear-ramp model by brute "
         "force, left out where its table would exceed 1.5e8 pixel-edge pairs). Slopes are least-squares "
         "fits of log time against log faces or log pixels.", "",
         "![scaling](img/speed_vs_error_scaling.png)", "",
         f"Slopes against faces: this renderer {_f(sf['softshadow'], '{:.2f}')}, the paper's algorithm "
         f"{_f(sf['paper'], '{:.2f}')}, naive {_f(sf['naive'], '{:.2f}')}. Against pixels: " +
         "; ".join(f"{name}: this renderer {_f(v['softshadow'], '{:.2f}')}, paper {_f(v['paper'], '{:.2f}')}, "
                   f"naive {_f(v['naive'], '{:.2f}')}" for name, v in scaling["slope_vs_pixels"].items()) + ".", "",
         "| case | faces | pixels | silhouette edges | this renderer (ms) | peak extra (MB) | paper (ms) | naive (ms) | naive vs this renderer (RMS) |",
         "|---|---:|---:|---:|---:|---:|---:|---:|---:|"]
    for x in scaling["by_faces"] + scaling["by_pixels"]:
        nv = x["naive"]
        L.append(f"| {x['case']} | {x['faces']} | {x['pixels']} | {x['silhouette_edges']} | "
                 f"{x['softshadow']['median_ms']:.1f} | {_f(x['softshadow'].get('peak_extra_mb'), '{:.0f}')} | "
                 f"{x['paper']['median_ms']:.1f} | "
                 f"{_f(nv.get('median_ms'), '{:.1f}') if 'median_ms' in nv else 'skipped'} | "
                 f"{_f(x.get('naive_vs_softshadow_rms'))} |")
    return L


def write_report(result: dict, md_path: Path, json_name: str | None = None) -> None:
    """docs/speed_vs_error.md and its plot (in ``img/`` beside it), from a sweep's result."""
    md_path = Path(md_path)
    img = md_path.parent / "img" / "speed_vs_error_pareto.png"
    pareto_plot(result, img)
    env, s = result["environment"], result["settings"]
    m, v = env["machine"], env["versions"]
    L = ["# Speed against error", "",
         "Generated by `softshadow bench --what sweep --json docs/speed_vs_error.json --report "
         "docs/speed_vs_error.md`; every figure below comes from that run's JSON. Timings are "
         "medians of repeated runs after compilation; the machine is shared, so compare figures "
         "of one run as ratios.", "",
         f"- Date: {env['date_utc']}",
         f"- Machine: {m['cpu']}, {m['cores']} cores, {m['memory_gb']} GB, {m['platform']}",
         "- Versions: " + ", ".join(f"{k} {val}" for k, val in v.items() if val), ""]
    L += [f"- Note: {n}" for n in result.get("notes", [])] + ([""] if result.get("notes") else [])
    L += [
         "## The scene and the truth", "",
         f"A top-down ground map of each mesh's shadow: sun azimuth {s['sun_azimuth_deg']} deg, elevation "
         f"{s['sun_elevation_deg']} deg, the real sun's disk (radius {s['sun_radius_deg']} deg), a uniform sky "
         f"with rho = {s['rho']}. The truth is a physical render by `data_synth`'s ray caster (sun disk plus "
         f"sky, direct light, pixel areas integrated) at {s['reference_pixels']} x {s['reference_pixels']} "
         f"with {s['reference_samples']} sun rays per pixel, cached on disk. Its own noise, measured as half "
         "the RMS difference of two independent halves, in the penumbra band:", "",
         "| mesh | faces | sun rays per pixel | reference noise (RMS, band) | band pixels | pixel (mm) | ray-casting s |",
         "|---|---:|---:|---:|---:|---:|---:|"]
    for name, r in result["reference"].items():
        faces = result[name]["faces"] if name in result else ""
        made = f"{r['seconds']:.0f}" if r["seconds"] else "cached"
        L.append(f"| {name} | {faces} | {r['samples']} | {r['noise_rms_band']:.4f} | {r['band_pixels']} | "
                 f"{1000 * r['pixel_m']:.1f} | {made} |")
    L += ["", "Errors are RMS differences of the shading (1 lit, rho umbra) to the truth, over the whole map "
          "and over the penumbra band (pixels seeing part of the sun's disk), the object's footprint left "
          "out; a render finer than the truth is block-averaged to it, a coarser one compared with the truth "
          "block-averaged to its own size. `dragon` is the real (MIT) Stanford dragon decimated to the "
          "paper's 26,584 faces; `knot` the built-in procedural stand-in. The linear profile uses the "
          "linear ramp closest to the sun's disk profile.", "",
          "![Pareto plot](img/speed_vs_error_pareto.png)", "", "## The meshes", ""]
    L += _case_table([(k, result[k]) for k in ("pillar", "ball", "dragon", "knot") if k in result])
    L += ["", "## Resolution (pillar)", ""]
    L += _case_table([(f"{c['pixels']} px", c) for c in result.get("resolution", [])])
    L += ["", "## Penumbra profile and precision (pillar)", ""]
    L += _case_table([(c["profile"], c) for c in result.get("profile", [])]
                     + [(c["dtype"], c) for c in result.get("dtype", [])])
    L += ["", "## Level of detail (the dragon, decimated; truth: the full dragon)", ""]
    L += _case_table([(f"{c['faces']} faces", c) for c in result.get("lod", [])])
    if result.get("fit_samples"):
        L += ["", "## Fits: samples per photo against the Cramer-Rao bound", "",
              "Same-model data (the pillar rendered by the project's own model, disk profile, Gaussian "
              "noise), fitted over noise seeds: the spread of the estimates against the mean one-sigma "
              "error the fit reports from its Jacobian (the Cramer-Rao bound of this Gaussian model), and "
              "the time per group after compilation.", "",
              "| samples per photo (cap) | used | seeds | k truth | k std | k CRB | std/CRB | bias/CRB | rho std | rho CRB | std/CRB | group s |",
              "|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|"]
        for r in result["fit_samples"]:
            k, rho = r["range_k"], r["rho"]
            L.append(f"| {r['samples_per_photo']} | {r.get('samples_used', '')} | {r['truth']['seeds']} | "
                     f"{r['truth']['range_k']} | {k['std']:.2e} | {k['crb']:.2e} | {k['std_over_crb']:.2f} | "
                     f"{k['bias_over_crb']:+.2f} | {rho['std']:.2e} | {rho['crb']:.2e} | {rho['std_over_crb']:.2f} | "
                     f"{r['group_seconds_after_compile']['median']:.2f} |")
    if "paper" in result:
        L += [""] + _paper_sections(result["paper"])
    if result.get("table1"):
        L += [""] + _table1_section(result["table1"])
    if result.get("scaling"):
        scaling_plot(result["scaling"], md_path.parent / "img" / "speed_vs_error_scaling.png")
        L += [""] + _scaling_section(result["scaling"])
    if json_name:
        L += ["", f"The raw figures: [{json_name}]({json_name})."]
    md_path.parent.mkdir(parents=True, exist_ok=True)
    md_path.write_text("\n".join(L) + "\n")


def report_from_json(json_path: Path, md_path: Path) -> None:
    write_report(json.loads(Path(json_path).read_text()), md_path, Path(json_path).name)
