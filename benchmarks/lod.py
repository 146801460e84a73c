"""Level of detail in the fitter, printed as JSON by ``softshadow bench --what lod``.

The real Stanford dragon (MIT remesh, 41,384 faces, vendored undecimated) stands in the
``dragon`` preset's scene (physical renderer, two handheld photos and a top-down map at 10:30);
each scene's folder is fitted in this process with the full mesh (``--lod off``), with the
automatic choice (``--lod auto``) and with fixed levels (``--lod FACES``). Each is fitted three
times: the first run compiles what it has not seen (new array shapes); the faster of the other two
is the warm time. The coarsest level (300 faces) is the ceiling: the rest of the fit does not
depend on the mesh, so no level of detail can save more than it does.

Scenes (``SCENES``): ``sun-1600``, the preset's 1600 x 1200 photos under the real sun (radius
0.2665 deg), where the photos show the dragon's detail; ``sun-640`` and ``haze-640``, the same
scene in 640 x 480 photos, under the real sun and under a 1 deg sun disk (a hazy sky's wider
penumbra), where they show less of it.

Per scene it also reports the full mesh's k and rho refitted with other sample seeds
(``FitOptions.seed``: other pixels of the same band), the spread a level's shift must be read
against, and (``fresh=True``) the wall time of ``softshadow fit`` in fresh processes, which
includes importing and loading (or compiling) the programs.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

__all__ = ["bench_lod", "SCENES"]

#: (name, (width, height), sun radius in degrees or None for the preset's real sun, in --quick)
SCENES = (("sun-1600", (1600, 1200), None, False),
          ("sun-640", (640, 480), None, True),
          ("haze-640", (640, 480), 1.0, True))

#: Fixed levels fitted besides off and auto (full run; --quick leaves 5,000 out). The last, the paper's
#: coarsest, is the ceiling: no level can save more than the time it leaves.
LEVELS = (20692, 5000, 1000, 300)


def _fit_runs(folder: Path, lod, seed: int = 0, warm_runs: int = 2) -> dict:
    """Fit three times: the first compiles what it has not seen; the warm time is the faster of
    the other two (on a shared machine the slower one mostly measures the neighbours)."""
    from fitting import FitOptions, fit_folder
    options = FitOptions(plots=False, lod=lod, seed=seed)
    runs = []
    for _ in range(1 + warm_runs):
        t = time.perf_counter()
        (g,) = fit_folder(folder, options=options).groups
        runs.append(time.perf_counter() - t)
    return {"lod": lod, "faces": g.lod_faces, "seconds_first": round(runs[0], 2), "seconds": round(min(runs[1:] or runs), 2),
            "range_k": g.range_k, "range_stderr": g.range_stderr, "range_stderr_stat": g.range_stderr_stat,
            "rho": g.rho, "rho_stderr": g.rho_stderr, "rho_stderr_stat": g.rho_stderr_stat,
            "rmse": g.rmse, "error": g.error}


def _warm_alternated(folder: Path, pairs: int = 4) -> dict:
    """``off`` and ``auto`` fitted alternately in this process (everything compiled and the levels
    kept already): medians of the wall and the process's CPU times and their ratios auto / off."""
    import numpy as np

    from fitting import FitOptions, fit_folder
    runs = {"off": [], "auto": []}
    for i in range(pairs):
        for lod in (("off", "auto") if i % 2 == 0 else ("auto", "off")):
            t, c = time.perf_counter(), time.process_time()
            fit_folder(folder, options=FitOptions(plots=False, lod=lod))
            runs[lod].append((round(time.perf_counter() - t, 3), round(time.process_time() - c, 3)))
    out = {lod: float(np.median([w for w, _ in r])) for lod, r in runs.items()}
    out.update({f"{lod}_cpu": float(np.median([c for _, c in r])) for lod, r in runs.items()})
    out["auto_over_off"] = round(out["auto"] / out["off"], 3)
    out["auto_over_off_cpu"] = round(out["auto_cpu"] / out["off_cpu"], 3)
    out["runs"] = runs
    return out


def _fresh_fit(folder: Path, lod: str, out: Path, cache: Path) -> tuple[float, float]:
    """Wall time and CPU time (s, user and system, of the process and its threads) of
    ``softshadow fit`` in a new process, with the compilation cache ``cache``."""
    import resource
    env = dict(os.environ, SOFTSHADOW_JAX_CACHE=str(cache))
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t = time.perf_counter()
    subprocess.run([sys.executable, "-m", "softshadow_cli", "fit", str(folder), "--out", str(out), "--force",
                    "--no-plots", "--lod", lod], check=True, env=env, stdout=subprocess.DEVNULL,
                   stderr=subprocess.DEVNULL)
    wall = time.perf_counter() - t
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    return round(wall, 2), round(cpu, 2)


def _fresh(folder: Path, tmp: Path, coarsest: int, pairs: int = 5) -> dict:
    """Fresh-process times: ``off`` with an empty compilation cache (compiles everything), then
    ``auto`` once (its own programs and levels into the caches), then ``pairs`` alternated runs
    of ``off`` and ``auto`` with the caches kept (the order flips each pair, so that neither
    always follows the other), and the coarsest level twice (the later counts). Medians of the
    alternated runs' wall and CPU times, and their ratios auto / off; the coarsest level's
    speed-up is the most any level of detail can give a user's ``softshadow fit``. The
    results of the last ``off`` and ``auto`` runs are read back for k and rho."""
    import numpy as np
    cache = tmp / "jax-cache"
    out = {lod: tmp / f"fresh-out-{lod}" for lod in ("off", "auto", str(coarsest))}
    times = {"off_empty_cache": _fresh_fit(folder, "off", out["off"], cache)[0]}
    _fresh_fit(folder, "auto", out["auto"], cache)
    runs = {"off": [], "auto": []}
    for i in range(pairs):
        for lod in (("off", "auto") if i % 2 == 0 else ("auto", "off")):
            runs[lod].append(_fresh_fit(folder, lod, out[lod], cache))
    _fresh_fit(folder, str(coarsest), out[str(coarsest)], cache)
    coarse = _fresh_fit(folder, str(coarsest), out[str(coarsest)], cache)
    for lod, r in runs.items():
        times[lod] = float(np.median([w for w, _ in r]))
        times[f"{lod}_cpu"] = float(np.median([c for _, c in r]))
        times[f"{lod}_runs"] = r
    times[str(coarsest)] = coarse[0]
    times["auto_over_off"] = round(times["auto"] / times["off"], 3)
    times["auto_over_off_cpu"] = round(times["auto_cpu"] / times["off_cpu"], 3)
    times["speedup_ceiling"] = round(times["off"] / coarse[0], 3)
    for lod in ("off", "auto"):
        (g,) = json.loads((out[lod] / "results.json").read_text())["groups"]
        times[f"{lod}_fit"] = {key: g.get(key) for key in ("range_k", "range_stderr", "rho", "rho_stderr",
                                                            "lod_faces")}
    fo, fa = times["off_fit"], times["auto_fit"]
    if fo["range_k"] is not None and fa["range_k"] is not None:
        times["auto_k_shift_se"] = round((fa["range_k"] - fo["range_k"]) / fo["range_stderr"], 3)
        times["auto_rho_shift_se"] = round((fa["rho"] - fo["rho"]) / fo["rho_stderr"], 3)
    return times


def _ceiling(rows: list[dict]) -> dict:
    """The most any level of detail can save: the fastest decimated level's warm speed-up over
    the full mesh (the coarsest levels leave only the work that does not depend on the mesh, so
    on a quiet machine it is the coarsest; on a shared one, whichever ran fastest), and the share
    of the full mesh's warm fit that the mesh accounts for (1 - fastest / full)."""
    full = rows[0]
    fastest = min((r for r in rows if r["lod"] not in ("off", "auto")), key=lambda r: r["seconds"])
    return {"faces": fastest["faces"], "speedup_warm": round(full["seconds"] / fastest["seconds"], 3),
            "mesh_share_warm": round(1.0 - fastest["seconds"] / full["seconds"], 3)}


def _shifts(row: dict, full: dict) -> None:
    """The row's shifts of k and rho from the full mesh's fit in its stated (and statistical)
    standard errors, and the warm speed-up."""
    if row["error"] is None and full["error"] is None:
        dk, dr = row["range_k"] - full["range_k"], row["rho"] - full["rho"]
        row["k_shift_se"], row["rho_shift_se"] = dk / full["range_stderr"], dr / full["rho_stderr"]
        row["k_shift_se_stat"] = dk / full["range_stderr_stat"]
        row["rho_shift_se_stat"] = dr / full["rho_stderr_stat"]
        row["speedup_warm"] = full["seconds"] / row["seconds"]


def bench_lod(quick: bool = False, seed: int = 0, progress=None, fresh: bool = True,
              scenes: tuple[str, ...] | None = None) -> dict:
    """Per scene: the truth, and per setting (off, auto, fixed levels) the faces fitted, the fit
    time (first run and warm second run, seconds, in this process), k and rho with their stated
    and statistical errors, their shifts from the full mesh's fit in its standard errors, the
    warm speed-up; the full mesh refitted with sample seeds 1 and 2; fresh-process times.
    scenes: names of ``SCENES`` to run (default: all, or those marked for --quick)."""
    from data_synth import synthesize

    from .meshes import mit_dragon
    mesh = mit_dragon(full=True)
    out = {"mesh": {"name": "MIT Stanford dragon remesh (wassersplines)", "faces": len(mesh.faces),
                    "watertight": bool(mesh.is_watertight)}, "seed": seed, "scenes": {}}
    levels = tuple(v for v in LEVELS if v != 5000) if quick else LEVELS
    with tempfile.TemporaryDirectory() as tmp:
        for name, size, radius, in_quick in SCENES:
            if (scenes is not None and name not in scenes) or (scenes is None and quick and not in_quick):
                continue
            folder = Path(tmp) / name
            synthesize(folder, preset="dragon", seed=seed, size=size, progress=False, object_mesh=mesh,
                       sun_radius_deg=radius)
            truth = json.loads((folder / "truth.json").read_text())["groups"][0]
            rows = []
            for lod in ("off", "auto", *levels):
                if progress:
                    progress(f"bench lod: {name} --lod {lod}")
                rows.append(_fit_runs(folder, lod))
            full = rows[0]
            for r in rows:
                _shifts(r, full)
            reseeded = []
            for s in (1, 2):
                r = _fit_runs(folder, "off", seed=s, warm_runs=0)
                _shifts(r, full)
                reseeded.append({key: r.get(key) for key in ("range_k", "rho", "k_shift_se", "rho_shift_se")})
            if progress:
                progress(f"bench lod: {name} off and auto alternated, warm")
            scene = {"size": list(size), "sun_radius_deg": radius or 0.2665, "truth_range_k": truth["range_k"],
                     "truth_rho": truth["rho"], "fits": rows, "full_mesh_other_seeds": reseeded,
                     "ceiling": _ceiling(rows), "warm_alternated": _warm_alternated(folder)}
            if fresh and in_quick:
                if progress:
                    progress(f"bench lod: {name} fresh processes")
                scene["fresh_process_seconds"] = _fresh(folder, Path(tmp) / f"{name}-fresh", levels[-1])
            out["scenes"][name] = scene
    return out


def bench_lod_fresh(scene: str = "sun-640", pairs: int = 4, seed: int = 0, progress=None) -> dict:
    """Only the fresh-process part of ``bench_lod`` for one scene (``_fresh``: ``softshadow fit``
    with ``--lod off`` and ``--lod auto`` alternated ``pairs`` times, caches kept), with the load
    average before and after."""
    from data_synth import synthesize

    from .environment import load_average
    from .meshes import mit_dragon
    name, size, radius, _ = next(s for s in SCENES if s[0] == scene)
    mesh = mit_dragon(full=True)
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp) / name
        synthesize(folder, preset="dragon", seed=seed, size=size, progress=False, object_mesh=mesh,
                   sun_radius_deg=radius)
        if progress:
            progress(f"bench lod: {name} fresh processes")
        before = load_average()
        times = _fresh(folder, Path(tmp) / f"{name}-fresh", LEVELS[-1], pairs=pairs)
        return {"scene": name, "size": list(size), "load_before": before, "load_after": load_average(),
                "fresh_process_seconds": times}
