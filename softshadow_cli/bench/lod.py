"""Level of detail in the fitter, printed as JSON by ``softshadow bench --what lod``.

The real Stanford dragon (MIT remesh, 41,384 faces, vendored undecimated) stands in the
``dragon`` preset's scene (physical renderer, two handheld photos and a top-down map at 10:30);
the folder is fitted in this process with the full mesh (``--lod off``), with the automatic
choice (``--lod auto``) and with fixed levels (``--lod FACES``). Each is fitted twice: the
first run compiles what it has not seen (new array shapes), the second is the warm time.
Scenes: ``sun``, the real sun (radius 0.2665 deg), and ``haze``, a sun disk of 1 deg radius
(a hazy sky's wider penumbra, which hides more of the mesh).
"""

from __future__ import annotations

import json
import tempfile
import time
from pathlib import Path

__all__ = ["bench_lod", "SCENES"]

#: (name, sun radius in degrees or None for the preset's real sun)
SCENES = (("sun", None), ("haze", 1.0))


def _fit_twice(folder: Path, lod) -> dict:
    from fitting import FitOptions, fit_folder
    options = FitOptions(plots=False, lod=lod)
    runs = []
    for _ in range(2):
        t = time.perf_counter()
        (g,) = fit_folder(folder, options=options).groups
        runs.append(time.perf_counter() - t)
    return {"lod": lod, "faces": g.lod_faces, "seconds_first": round(runs[0], 2), "seconds": round(runs[1], 2),
            "range_k": g.range_k, "range_stderr": g.range_stderr, "rho": g.rho, "rho_stderr": g.rho_stderr,
            "rmse": g.rmse, "error": g.error}


def bench_lod(quick: bool = False, seed: int = 0, progress=None) -> dict:
    """Per scene: the truth, and per setting (off, auto, fixed levels) the faces fitted, the fit
    time (first run and warm second run, seconds, in this process), k and rho with their errors,
    their shifts from the full mesh's fit in its standard errors, and the warm speed-up."""
    from data_synth import synthesize

    from .meshes import mit_dragon
    size = (800, 600) if quick else (1600, 1200)
    levels = (5000, 1000, 300) if quick else (20692, 10346, 5000, 1000, 300)
    mesh = mit_dragon(full=True)
    out = {"mesh": {"name": "MIT Stanford dragon remesh (wassersplines)", "faces": len(mesh.faces),
                    "watertight": bool(mesh.is_watertight)}, "size": list(size), "seed": seed, "scenes": {}}
    with tempfile.TemporaryDirectory() as tmp:
        for name, radius in SCENES:
            folder = Path(tmp) / name
            synthesize(folder, preset="dragon", seed=seed, size=size, progress=False, object_mesh=mesh,
                       sun_radius_deg=radius)
            truth = json.loads((folder / "truth.json").read_text())["groups"][0]
            rows = []
            for lod in ("off", "auto", *levels):
                if progress:
                    progress(f"bench lod: {name} --lod {lod}")
                rows.append(_fit_twice(folder, lod))
            full = rows[0]
            for r in rows:
                if r["error"] is None and full["error"] is None:
                    r["k_shift_se"] = (r["range_k"] - full["range_k"]) / full["range_stderr"]
                    r["rho_shift_se"] = (r["rho"] - full["rho"]) / full["rho_stderr"]
                    r["speedup_warm"] = full["seconds"] / r["seconds"]
            out["scenes"][name] = {"sun_radius_deg": radius or 0.2665, "truth_range_k": truth["range_k"],
                                   "truth_rho": truth["rho"], "fits": rows}
    return out
