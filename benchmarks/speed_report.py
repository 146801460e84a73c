"""The speed-against-error report: a Pareto plot (PNG) and ``docs/speed_vs_error.md``, made only
from the JSON a sweep wrote (no figure is typed in)."""

from __future__ import annotations

from pathlib import Path

__all__ = ["image_cases", "pareto_front", "pareto_plot", "write_report", "write_overview_report"]


def image_cases(result: dict) -> list[tuple[str, str, dict]]:
    """(mesh, label, case) of every timed render that has an image error."""
    out = []
    for key in ("pillar", "ball", "dragon", "knot"):
        if key in result:
            out.append((key, f"{result[key]['pixels']} px", result[key]))
    for key, c in result.get("wedge", {}).items():
        out.append((key, f"wedge {c['pixels']} px", c))
    for c in result.get("resolution", []):
        out.append(("pillar", f"{c['pixels']} px", c))
    for c in result.get("profile", []):
        out.append(("pillar", c["profile"], c))
    for c in result.get("dtype", []):
        out.append(("pillar", c["dtype"], c))
    for c in result.get("lod", []):
        out.append(("dragon", f"{c['faces']} faces", c))
    for name, row in result.get("paper", {}).get("table3", {}).items():
        out.append((name, "paper soft", row["soft"]))
        out.append((name, "paper hard", row["hard"]))
    for name, peer in mitsuba_runs(result).items():
        for c in peer["cases"]:
            out.append((name, f"{c['spp']} spp", c))
    return out


def mitsuba_runs(result: dict) -> dict:
    """{mesh: Mitsuba run} of the sweep ({} when it was skipped)."""
    m = result.get("mitsuba") or {}
    return {} if "skipped" in m else m


def _renderer(case: dict) -> str:
    name = case.get("renderer", "softshadow")
    return f"{name} (wedge)" if case.get("rule") == "wedge" else name


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
    """Time against penumbra-band error of every image case (log-log), one panel per mesh, each
    with its own Pareto front."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    cases = [x for x in image_cases(result) if x[2]["error"].get("rms_band") is not None]
    meshes = list(dict.fromkeys(m for m, _, _ in cases))
    cols = 2 if len(meshes) > 1 else 1
    rows = (len(meshes) + cols - 1) // cols
    fig, axes = plt.subplots(rows, cols, figsize=(6.5 * cols, 4.8 * rows), squeeze=False)
    markers = {"softshadow": "o", "softshadow (wedge)": "D", "paper": "s", "paper (hard)": "v", "mitsuba": "^"}
    for ax, mesh in zip(axes.ravel(), meshes):
        mine = [(lab, c) for m, lab, c in cases if m == mesh]
        groups = {}
        for lab, c in mine:
            groups.setdefault(_renderer(c), []).append((lab, c))
        for renderer, items in groups.items():
            ax.scatter([c["median_ms"] for _, c in items], [c["error"]["rms_band"] for _, c in items],
                       label=renderer, s=22, marker=markers.get(renderer, "o"))
            for lab, c in items:
                ax.annotate(lab, (c["median_ms"], c["error"]["rms_band"]), fontsize=6, xytext=(3, 2),
                            textcoords="offset points")
        pts = [(c["median_ms"], c["error"]["rms_band"]) for _, c in mine]
        front = pareto_front(pts)
        ax.plot([pts[i][0] for i in front], [pts[i][1] for i in front], "k--", lw=0.8, label="Pareto front")
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xlabel("median wall time per render after compilation (ms)")
        ax.set_ylabel("RMS shading error, penumbra band")
        ax.set_title(mesh)
        ax.legend(fontsize=7)
        ax.grid(True, which="both", lw=0.3)
    for ax in axes.ravel()[len(meshes):]:
        ax.set_visible(False)
    fig.suptitle("Speed against error (top-down ground map, real sun; truth: converged physical render)")
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)


def pareto_table(result: dict) -> list[str]:
    """The Pareto front of each mesh as a table (the plot's dashed lines)."""
    cases = [x for x in image_cases(result) if x[2]["error"].get("rms_band") is not None]
    L = ["| mesh | on the front (fastest first) | renderer | time (ms) | RMS band |", "|---|---|---|---:|---:|"]
    for mesh in dict.fromkeys(m for m, _, _ in cases):
        mine = [(lab, c) for m, lab, c in cases if m == mesh]
        pts = [(c["median_ms"], c["error"]["rms_band"]) for _, c in mine]
        for i in pareto_front(pts):
            lab, c = mine[i]
            L.append(f"| {mesh} | {lab} | {_renderer(c)} | {c['median_ms']:.1f} | "
                     f"{c['error']['rms_band']:.4f} |")
    return L


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
         "The paper's section 3.2 as written (`benchmarks/shoji.py`, NumPy/OpenCV): the "
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


def _load(x) -> str:
    return "n/a" if not x else " / ".join(f"{v:.1f}" for v in x)


def _ms(r: dict) -> str:
    return f"{r['mitsuba_ms']:.0f}" if r["mitsuba_ms"] is not None else "not reached"


def _ratio(r: dict) -> str:
    if r["ratio"] is not None:
        return f"{r['ratio']:.0f}"
    return f"> {r['ratio_at_least']:.0f}" if r.get("ratio_at_least") else "n/a"


_MEASURES = {"rms": "whole map", "rms_band": "penumbra band", "noise_band": "penumbra band, Mitsuba's noise only"}


def _setups_section(setups: dict) -> list[str]:
    """Mitsuba's set-ups against each other (``mitsuba_setups`` of the sweep)."""
    L = ["## Mitsuba's set-ups", ""]
    if "skipped" in setups:
        return L + [f"Skipped: {setups['skipped']}."]
    L += ["Where Mitsuba's error comes from, and which of its set-ups reaches a given error fastest. The same "
          "light throughout (the sun's disk, radius and irradiance, and the uniform sky; direct light; box "
          "pixel filter), sampled in different ways: `disk sun` is a uniform disk area light 100 km away "
          "beside a constant sky emitter, `envmap sun` one environment map holding the sun's disk (on the "
          "map's pole, so that the disk is whole rows) and the sky, importance-sampled as a whole; the "
          "sampler; the sun's share of the light samples (Mitsuba's emitter `sampling_weight`; by default "
          "the two emitters are picked alike); light + BSDF samples per camera sample (the `direct` "
          "integrator's `emitter_samples`, `bsdf_samples`). Every set-up but one lowers the ground by Mitsuba's "
          "shadow-ray offset (float32 Mitsuba starts a shadow ray (1 + max |coordinate|) x 8.9e-5 m along the "
          "normal, about 0.18 mm at 1 m from the origin, which moves a penumbra by that over tan(elevation)), so "
          "that its shadow rays leave from z = 0 as the truth's do; `ground at z = 0` leaves it. Each set-up renders the map twice at the same "
          "spp, timed round-robin: the band's noise is half the RMS difference of the two renders times "
          "sqrt 2 (RMS(a - b) / sqrt 2), the floor is the error against the truth that is not that noise "
          "(sqrt(error^2 - noise^2): Mitsuba's bias against the truth plus the truth's own noise, quoted "
          "beside it), and the efficiency is 1 / (noise^2 x time) over the plain set-up's: how many times "
          "faster a set-up reaches equal noise.", "",
          "| mesh | set-up | spp | time (ms) | RMS band | band noise | floor | truth's noise | efficiency | RMS |",
          "|---|---|---:|---:|---:|---:|---:|---:|---:|---:|"]
    for mesh, rows in setups.items():
        for r in rows:
            L.append(f"| {mesh} | {r['setup']} | {r['spp']} | {r['median_ms']:.0f} | {_f(r['error']['rms_band'])} | "
                     f"{r['noise_rms_band']:.4f} | {r['floor_rms_band']:.4f} | {_f(r.get('reference_noise_rms_band'))} | "
                     f"{r['efficiency']:.2f} | {_f(r['error']['rms'])} |")
    return L


def _mitsuba_section(mitsuba: dict) -> list[str]:
    L = ["## Mitsuba 3, measured in the same run", ""]
    if "skipped" in mitsuba:
        return L + [f"Skipped: {mitsuba['skipped']} (`pip install 'softshadow[peers]'`)."]
    runs = list(mitsuba.values())
    if runs[0]["variant"].startswith("scalar"):
        L += ["drjit's LLVM backend did not render on this machine, so Mitsuba ran its scalar variant, several "
              "times slower than its LLVM one: set `DRJIT_LIBLLVM_PATH` to a libLLVM that works with it "
              "(`benchmarks.mitsuba_peer`).", ""]
    L += [f"Mitsuba 3 (`{runs[0]['variant']}` variant) path-traces the same scene in the set-up that reached "
          f"a given noise fastest above ({runs[0].get('setup_label', 'disk sun')}): the mesh on a Lambertian "
          "ground, the sun's disk and the uniform sky, direct light only (`direct` integrator), an "
          "orthographic top-down camera over the same square with a box pixel filter, at the truth's size. "
          "Time is the median wall time of renders after a first render at the same samples per pixel "
          "(spp), which compiles its kernel and is the image compared with the same converged physical "
          "truth as every other case; the band's noise and floor as above, from that render and a timed one.",
          "", "| mesh | spp | pixels | time (ms) | RMS | RMS band | band noise | floor | max abs |",
          "|---|---:|---:|---:|---:|---:|---:|---:|---:|"]
    for name, run in mitsuba.items():
        for c in run["cases"]:
            e = c["error"]
            L.append(f"| {name} | {c['spp']} | {c['pixels']} | {c['median_ms']:.0f} | {_f(e['rms'])} | "
                     f"{_f(e['rms_band'])} | {_f(c.get('noise_rms_band'))} | {_f(c.get('floor_rms_band'))} | "
                     f"{_f(e['max_abs'], '{:.3f}')} |")
    L += ["", "The time Mitsuba needs to reach this renderer's error on the same mesh and map, both timed warm in "
          "this run: log-log interpolation between the measured spp, or past the last one with Monte Carlo's "
          "noise ~ time^-1/2 above the floor measured at the last spp (the whole map: error ~ time^-1/2); "
          "`not reached` where this renderer's error lies below Mitsuba's floor against the truth, the ratio "
          "then a lower bound (Mitsuba's longest render, which did not reach it, over this renderer's time). "
          "`Mitsuba's noise only` measures Mitsuba as against its own converged render (its band noise "
          "from two renders reaching this renderer's band error against the truth): the comparison as if "
          "Mitsuba's floor were the truth's fault.",
          "", "| mesh | renderer | error measure | this renderer's error | this renderer (ms) | Mitsuba (ms) | how | ratio |",
          "|---|---|---|---:|---:|---:|---|---:|"]
    for name, run in mitsuba.items():
        for renderer, reach in run["time_to_reach"].items():
            for metric, r in reach.items():
                L.append(f"| {name} | {renderer} | {_MEASURES[metric]} | {r['target']:.4f} | "
                         f"{r['softshadow_ms']:.1f} | {_ms(r)} | {r['how']} | {_ratio(r)} |")
    L += [""] + [line for name, run in mitsuba.items() for line in _levels_off(name, run["cases"])]
    for name, run in mitsuba.items():
        last, ref = run["cases"][-1], run.get("reference_noise_rms_band")
        if ref is not None and last.get("floor_rms_band") is not None:
            beyond = max(last["floor_rms_band"] ** 2 - ref ** 2, 0.0) ** 0.5
            L.append(f"- {name}: at {last['spp']} spp Mitsuba's band error {last['error']['rms_band']:.4f} is its "
                     f"noise {last['noise_rms_band']:.4f} and a floor {last['floor_rms_band']:.4f}; the truth's own "
                     f"noise is {ref:.4f}, so the two physical renders differ by {beyond:.4f} (RMS, band) beyond "
                     "both renders' noise.")
    return L


def _levels_off(name: str, cases: list[dict]) -> list[str]:
    """A note where Mitsuba's last spp step lowered its error much less than Monte Carlo noise
    alone would (error ~ spp^-1/2): it levels off against this truth, and an extrapolated time
    is then no more than a lower bound of a level it may not reach."""
    if len(cases) < 2:
        return []
    a, b = cases[-2], cases[-1]
    out = []
    for metric, label in (("rms", "whole-map"), ("rms_band", "penumbra-band")):
        drop, noise_drop = a["error"][metric] / b["error"][metric], (b["spp"] / a["spp"]) ** 0.5
        if drop < 1.0 + 0.5 * (noise_drop - 1.0):
            out.append(f"- {name}: from {a['spp']} to {b['spp']} spp Mitsuba's {label} error fell {drop:.2f}x "
                       f"where noise alone falls {noise_drop:.1f}x: it levels off near {b['error'][metric]:.4f} "
                       "against this truth (a difference between the two physical renders, not noise), so an "
                       "extrapolated time above is a lower bound at best.")
    return out


def _save_loglog_panels(fig, axes, ylabel: str, path: Path, dpi: int) -> None:
    """Log-log axes with a grid and a legend on every panel; the figure written to ``path``."""
    import matplotlib.pyplot as plt
    for ax in axes:
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_ylabel(ylabel)
        ax.grid(True, which="both", lw=0.3)
        ax.legend(fontsize=7)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=dpi)
    plt.close(fig)


def fit_scaling_plot(fb: dict, path: Path) -> None:
    """The fit's time against photos per group and against samples (log-log), both solvers."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, axes = plt.subplots(1, 2, figsize=(10, 4.0))
    for solver, style in (("autodiff", "o-"), ("finite_differences", "s--")):
        ph = sorted(fb["by_photos"].items(), key=lambda kv: int(kv[0]))
        axes[0].plot([int(n) for n, _ in ph], [v[solver]["median_ms"] for _, v in ph], style, label=solver)
        cp = sorted(fb["by_cap"].values(), key=lambda v: v["samples"])
        axes[1].plot([v["samples"] for v in cp], [v[solver]["median_ms"] for v in cp], style, label=solver)
    axes[0].set_xlabel(f"photos per group ({fb['cap_for_photos']} samples per photo at most)")
    axes[1].set_xlabel("samples (one photo)")
    _save_loglog_panels(fig, axes, "median ms per solve", path, dpi=110)


def _fit_baseline_section(fb: dict) -> list[str]:
    t = fb["truth"]
    L = ["## The same fit without autodiff (baseline 6)", "",
         "One group's plain least-squares problem as the fitter builds it (`fitting.group_problem`: its "
         "samples, its start, its residual function) solved twice in the same process: by the fitter's own "
         "solve (optimistix Levenberg-Marquardt, Jacobian by autodiff, plus the Jacobian at the solution for "
         "the errors) and by `scipy.optimize.least_squares` (trust region reflective, default tolerances) "
         "with a 2-point finite-difference Jacobian of the same residual function. The data: the pillar "
         f"rendered top-down by the project's own model (disk profile, k = {t['range_k']}, rho = {t['rho']}, "
         f"Gaussian noise sigma {t['noise_sigma']}), one noise draw per photo. Times are medians after "
         "compilation; errors over the groups (RMS).", "",
         "| photos per group | samples per photo (cap) | samples | parameters | groups | autodiff (ms) | "
         "finite differences (ms) | FD / autodiff | k error autodiff | k error FD | rho error autodiff | "
         "rho error FD | max k difference FD - autodiff |",
         "|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|"]
    rows = [(n, fb["cap_for_photos"], v) for n, v in fb["by_photos"].items()]
    rows += [(1, int(c), v) for c, v in fb["by_cap"].items() if int(c) != fb["cap_for_photos"]]
    for n, cap, v in rows:
        ad, fd = v["autodiff"], v["finite_differences"]
        L.append(f"| {n} | {cap} | {v['samples']} | {v['parameters']} | {v['groups']} | {ad['median_ms']:.0f} | "
                 f"{fd['median_ms']:.0f} | {v['time_ratio_fd_over_autodiff']:.1f} | {100 * ad['k_rel_rms']:.2f} % | "
                 f"{100 * fd['k_rel_rms']:.2f} % | {ad['rho_abs_rms']:.4f} | {fd['rho_abs_rms']:.4f} | "
                 f"{100 * v['k_fd_minus_autodiff_max_rel']:.4f} % |")
    sp, ss = fb["slope_vs_photos"], fb["slope_vs_samples"]
    L += ["", f"Log-log slopes of time: against photos per group, autodiff {_f(sp['autodiff'], '{:.2f}')}, "
          f"finite differences {_f(sp['finite_differences'], '{:.2f}')}; against samples (one photo), "
          f"autodiff {_f(ss['autodiff'], '{:.2f}')}, finite differences {_f(ss['finite_differences'], '{:.2f}')}. "
          "Finite differences need p + 1 residual evaluations per Jacobian (p = 5 + 4 x photos parameters).",
          "", "![fit scaling](img/speed_vs_error_fit.png)"]
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
    _save_loglog_panels(fig, axes, "median ms", path, dpi=120)


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
                   f"naive {_f(v['naive'], '{:.2f}')}" for name, v in scaling["slope_vs_pixels"].items()) + "."]
    if "memory_slope_vs_faces" in scaling:
        mf = scaling["memory_slope_vs_faces"]
        L += ["", "Peak memory (MB above the resident set before the run, over one untimed run after the timed "
              "ones, with glibc's free heap pages handed back first so that XLA's CPU buffers show), log-log "
              f"slopes: against faces, this renderer {_f(mf['softshadow'], '{:.2f}')}, the paper's algorithm "
              f"{_f(mf.get('paper'), '{:.2f}')}, naive {_f(mf['naive'], '{:.2f}')}; against pixels, " +
              "; ".join(f"{name}: this renderer {_f(v['softshadow'], '{:.2f}')}, paper {_f(v.get('paper'), '{:.2f}')}, "
                        f"naive {_f(v['naive'], '{:.2f}')}"
                        for name, v in scaling["memory_slope_vs_pixels"].items()) +
              " (n/a: fewer than two cases measured)."]
    cm = scaling.get("cost_model", {})
    if "pixels_plus_edges" in cm:
        a, b = cm["pixels_plus_edges"], cm["pixels_times_edges"]
        better = a["rms_rel_residual"] < b["rms_rel_residual"]
        verdict = ("so the measurement supports the claim that cost grows with pixels plus silhouette edges "
                   "(not with their product)" if better else
                   "so this run does not support the claim over the product law")
        L += ["", "**Cost grows with pixels plus silhouette edges?** This renderer's times over all the cases "
              f"below ({cm['points']}) fitted (non-negative least squares, relative residuals) as "
              f"t = {a['ms']:.2f} ms + {a['ms_per_megapixel']:.1f} ms per megapixel + "
              f"{a['ms_per_thousand_edges']:.2f} ms per thousand silhouette edges leave an RMS relative "
              f"residual of {100 * a['rms_rel_residual']:.0f} % (largest {100 * a['max_rel_residual']:.0f} %); the "
              f"naive renderer's law t = {b['ms']:.2f} ms + {b['ms_per_giga_pixel_edges']:.2f} ms per 10^9 "
              f"pixel-edge pairs leaves {100 * b['rms_rel_residual']:.0f} % (largest "
              f"{100 * b['max_rel_residual']:.0f} %): {verdict}."]
    L += ["",
         "| case | faces | pixels | silhouette edges | this renderer (ms) | peak extra (MB) | paper (ms) | naive (ms) | naive peak extra (MB) | naive vs this renderer (RMS) |",
         "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|"]
    for x in scaling["by_faces"] + scaling["by_pixels"]:
        nv = x["naive"]
        L.append(f"| {x['case']} | {x['faces']} | {x['pixels']} | {x['silhouette_edges']} | "
                 f"{x['softshadow']['median_ms']:.1f} | {_f(x['softshadow'].get('peak_extra_mb'), '{:.0f}')} | "
                 f"{x['paper']['median_ms']:.1f} | "
                 f"{_f(nv.get('median_ms'), '{:.1f}') if 'median_ms' in nv else 'skipped'} | "
                 f"{_f(nv.get('peak_extra_mb'), '{:.0f}')} | {_f(x.get('naive_vs_softshadow_rms'))} |")
    return L


def _header(result: dict, title: str, command: str) -> list[str]:
    """Title, the command that made the report, date, machine, load, run time and versions."""
    env, s = result["environment"], result["settings"]
    m, v = env["machine"], env["versions"]
    return [f"# {title}", "",
            f"Generated by `{command}`; every figure below comes from that run's JSON. Timings are "
            "medians of repeated runs after compilation; the machine is shared, so compare figures "
            "of one run as ratios.", "",
            f"- Date: {env['date_utc']}",
            f"- Machine: {m['cpu']}, {m['cores']} cores, {m['memory_gb']} GB, {m['platform']}",
            f"- Load average (1, 5, 15 min): {_load(m.get('load_average_1_5_15_min'))} at the start, "
            f"{_load(env.get('load_average_at_end'))} at the end (runnable processes on the "
            f"{m['cores']} cores: above {m['cores']} the machine was shared)",
            f"- The run took {env.get('run_minutes', 'n/a')} minutes (finished {env.get('finished_utc', 'n/a')}); "
            f"{'quick' if s.get('quick') else 'full'} sizes",
            "- Versions: " + ", ".join(f"{k} {val}" for k, val in v.items() if val), ""]


def write_report(result: dict, md_path: Path, json_name: str | None = None) -> None:
    """docs/speed_vs_error.md and its plot (in ``img/`` beside it), from a sweep's result."""
    md_path = Path(md_path)
    img = md_path.parent / "img" / "speed_vs_error_pareto.png"
    pareto_plot(result, img)
    s = result["settings"]
    L = _header(result, "Speed against error", "softshadow bench --what sweep --json docs/speed_vs_error.json "
                "--report docs/speed_vs_error.md")
    L += [
         "## The scene and the truth", "",

         f"A top-down ground map of each mesh's shadow: sun azimuth {s['sun_azimuth_deg']} deg, elevation "
         f"{s['sun_elevation_deg']} deg, the real sun's disk (radius {s['sun_radius_deg']} deg), a uniform sky "
         f"with rho = {s['rho']}. The truth is a physical render by `data_synth`'s ray caster (sun disk plus "
         f"sky, direct light, pixel areas integrated; the hidden sky from `data_synth`'s sky map, traced "
         f"pixel by pixel next to the object, where the map's interpolation between nodes inside and "
         f"outside the object read up to 0.13 too dark before 2026-11-24 evening) at {s['reference_pixels']} x {s['reference_pixels']} "
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
          "![Pareto plot](img/speed_vs_error_pareto.png)", "",
          "The Pareto front of each mesh (no other case of that mesh is both faster and closer to the truth):",
          ""] + pareto_table(result) + ["", "## The meshes", ""]
    L += _case_table([(k, result[k]) for k in ("pillar", "ball", "dragon", "knot") if k in result]
                     + [(f"{k} (wedge rule)", c) for k, c in result.get("wedge", {}).items()])
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
    if result.get("fit_baseline"):
        fit_scaling_plot(result["fit_baseline"], md_path.parent / "img" / "speed_vs_error_fit.png")
        L += [""] + _fit_baseline_section(result["fit_baseline"])
    if "paper" in result:
        L += [""] + _paper_sections(result["paper"])
    if "mitsuba_setups" in result:
        L += [""] + _setups_section(result["mitsuba_setups"])
    if "mitsuba" in result:
        L += [""] + _mitsuba_section(result["mitsuba"])
    if result.get("table1"):
        L += [""] + _table1_section(result["table1"])
    if result.get("scaling"):
        scaling_plot(result["scaling"], md_path.parent / "img" / "speed_vs_error_scaling.png")
        L += [""] + _scaling_section(result["scaling"])
    if json_name:
        L += ["", f"The raw figures: [{json_name}]({json_name})."]
    md_path.parent.mkdir(parents=True, exist_ok=True)
    md_path.write_text("\n".join(L) + "\n")


def write_overview_report(result: dict, md_path: Path, json_name: str | None = None) -> None:
    """docs/benchmarks.md: the plain ``softshadow bench`` (``overview``) as tables, from its JSON."""
    s = result["settings"]
    L = _header(result, "Benchmarks: every renderer against the same truth",
                "softshadow bench --json docs/benchmarks.json --report docs/benchmarks.md")
    L += ["`softshadow bench` without `--what` renders the pillar (176 faces), the ball (1,472) and the real "
          f"dragon (26,584) as {s['reference_pixels']} x {s['reference_pixels']} top-down ground maps under the "
          f"real sun (azimuth {s['sun_azimuth_deg']} deg, elevation {s['sun_elevation_deg']} deg, disk radius "
          f"{s['sun_radius_deg']} deg, sky rho = {s['rho']}) with every renderer, and compares each with a "
          f"physical render of the same map by `data_synth`'s ray caster ({s['reference_samples']} sun rays per "
          "pixel, pixel areas integrated, cached on disk). Errors are RMS differences of the shading (1 lit, "
          "rho umbra) over the map and over the penumbra band, the object's footprint left out. "
          "The full sweep (resolutions, profiles, precision, level of detail, fits, Tables 1-3, scaling) "
          "is `--what sweep`: [speed_vs_error.md](speed_vs_error.md).", "",
          "- softshadow: this renderer (linear profile, float32); its JSON keys are the mesh names.",
          "- softshadow (wedge): its `wedge` rule, the sun's hidden fraction from the silhouette edges "
          "(disk profile, float32, [renderer.md](renderer.md#the-wedge-rule)); key `wedge`.",
          "- paper (hard) / paper: the Shoji paper's own algorithm (section 3.2, NumPy/OpenCV), the "
          "stencil volume alone and the whole soft algorithm with its range and expansion fitted to the "
          "truth; key `paper`.",
          "- naive: every pixel against every silhouette edge, the same linear ramp; key `naive`.",
          "- mitsuba: Mitsuba 3 path-tracing the same scene (sun disk, sky, direct light, box pixel "
          "filter) at several samples per pixel; key `mitsuba`.", "",
          "| mesh | renderer | setting | time (ms) | x this renderer | RMS | RMS band |",
          "|---|---|---|---:|---:|---:|---:|"]
    for r in result["summary"]:
        L.append(f"| {r['mesh']} | {r['renderer']} | {r['setting']} | {r['median_ms']:.1f} | "
                 f"{r['times_softshadow']:.2f} | {_f(r['rms'])} | {_f(r['rms_band'])} |")
    runs = mitsuba_runs(result)
    if runs:
        L += ["", "The time Mitsuba needs to reach this renderer's error (log-log interpolation between the "
              "measured spp, or past the last one with error ~ time^-1/2):", "",
              "| mesh | error measure | this renderer's error | Mitsuba (ms) | how | ratio |",
              "|---|---|---:|---:|---|---:|"]
        for name, run in runs.items():
            for renderer, reach in run["time_to_reach"].items():
                for metric, r in reach.items():
                    label = name if renderer == "softshadow" else f"{name} ({renderer})"
                    L.append(f"| {label} | {_MEASURES[metric]} | {r['target']:.4f} | {_ms(r)} | {r['how']} | "
                             f"{_ratio(r)} |")
    else:
        L += ["", f"Mitsuba: skipped: {result['mitsuba'].get('skipped', 'not run')} "
              "(`pip install 'softshadow[peers]'`)."]
    if json_name:
        L += ["", f"The raw figures: [{json_name}]({json_name})."]
    md_path = Path(md_path)
    md_path.parent.mkdir(parents=True, exist_ok=True)
    md_path.write_text("\n".join(L) + "\n")
