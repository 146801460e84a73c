"""Fits of the real dragon under each penumbra rule and level of detail, printed as JSON by
``softshadow bench --what dragon-fit``.

The real Stanford dragon (MIT remesh, 41,384 faces) stands in the ``dragon`` preset's scene
(``data_synth``'s physical renderer: two handheld photos and a top-down map at 10:30, the real
sun's 0.2665 deg radius). The folder is fitted with the full mesh (``--lod off``) and with the
project's levels of detail at 5,000 and 1,000 faces (``--lod FACES``), each with the ``edge`` rule,
the ``wedge`` rule and ``auto`` (``FitOptions.rule``). Per fit: k and rho, their stated errors,
their bias against the truth in % and in stated errors, the rule used and the criterion of the
choice, and the fit's time (the first fit of a rule compiles its solver).
"""

from __future__ import annotations

import json
import tempfile
import time
from pathlib import Path

__all__ = ["bench_dragon_fit", "RULES", "LEVELS", "SIZE"]

RULES = ("edge", "wedge", "auto")
#: Levels fitted: the full mesh, then the fitter's levels of detail (faces).
LEVELS = ("off", 5000, 1000)
#: Photo size (px): the penumbra spans 2-3 px in the handheld photos.
SIZE = (1024, 768)
QUICK_SIZE = (640, 480)


def _fit(folder: Path, rule: str, lod, truth: dict) -> dict:
    from fitting import FitOptions, fit_folder
    t = time.perf_counter()
    (g,) = fit_folder(folder, options=FitOptions(plots=False, rule=rule, lod=lod)).groups
    seconds = time.perf_counter() - t
    row = {"rule_asked": rule, "lod": lod, "faces": g.lod_faces, "rule": g.rule, "rule_criterion": g.rule_criterion,
           "range_k": g.range_k, "range_stderr": g.range_stderr, "range_stderr_stat": g.range_stderr_stat,
           "rho": g.rho, "rho_stderr": g.rho_stderr, "rmse": g.rmse, "reliable": g.reliable, "error": g.error,
           "seconds": round(seconds, 2)}
    if g.range_k is not None:
        k_true, rho_true = truth["range_k"], truth["rho"]
        row["k_bias_pct"] = 100.0 * (g.range_k - k_true) / k_true
        row["k_bias_se"] = (g.range_k - k_true) / g.range_stderr if g.range_stderr else None
        row["rho_bias"] = g.rho - rho_true
        row["rho_bias_se"] = (g.rho - rho_true) / g.rho_stderr if g.rho_stderr else None
    return row


def bench_dragon_fit(quick: bool = False, seed: int = 0, progress=None) -> dict:
    """The truth and, per rule and level of detail, the fit (``_fit``'s row); ``quick``: 640 x 480
    photos instead of 1024 x 768."""
    from data_synth import synthesize

    from .meshes import mit_dragon
    mesh = mit_dragon(full=True)
    size = QUICK_SIZE if quick else SIZE
    out = {"mesh": {"name": "MIT Stanford dragon remesh (wassersplines)", "faces": len(mesh.faces)},
           "seed": seed, "size": list(size), "fits": []}
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp) / "dragon"
        if progress:
            progress(f"bench dragon-fit: synthesising {size[0]}x{size[1]}")
        synthesize(folder, preset="dragon", seed=seed, size=size, progress=False, object_mesh=mesh)
        truth = json.loads((folder / "truth.json").read_text())["groups"][0]
        out["truth"] = {"range_k": truth["range_k"], "rho": truth["rho"]}
        for rule in RULES:
            for lod in LEVELS:
                if progress:
                    progress(f"bench dragon-fit: rule {rule}, lod {lod}")
                out["fits"].append(_fit(folder, rule, lod, truth))
    return out


def markdown_table(result: dict) -> str:
    """The fits as a Markdown table (docs/level_of_detail.md)."""
    lines = ["| rule asked | faces | rule used (criterion, se) | k (x 1e-3) | k bias % | k bias / se | rho | "
             "rho bias | rho bias / se | reliable | seconds |", "|---|---:|---|---:|---:|---:|---:|---:|---:|---|---:|"]
    f = lambda x, fmt: "-" if x is None else format(x, fmt)
    for r in result["fits"]:
        crit = "" if r.get("rule_criterion") is None else f" ({r['rule_criterion']:.2f})"
        lines.append(f"| {r['rule_asked']} | {r['faces']} | {r['rule']}{crit} | "
                     f"{f(1e3 * r['range_k'] if r['range_k'] is not None else None, '.3f')} "
                     f"± {f(1e3 * r['range_stderr'] if r['range_stderr'] else None, '.3f')} | "
                     f"{f(r.get('k_bias_pct'), '+.1f')} | {f(r.get('k_bias_se'), '+.2f')} | "
                     f"{f(r['rho'], '.4f')} ± {f(r['rho_stderr'], '.4f')} | {f(r.get('rho_bias'), '+.4f')} | "
                     f"{f(r.get('rho_bias_se'), '+.2f')} | {'yes' if r.get('reliable') else 'no'} | "
                     f"{r['seconds']:.1f} |")
    return "\n".join(lines)
