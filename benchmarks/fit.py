"""Fitter benchmarks (speed against error), printed as JSON by ``softshadow bench --what fit``.

- ``same_model``: top-down renders of the pillar by the project's own model (disk profile,
  pixels integrate 4 x 4 point samples) with Gaussian noise, fitted over many noise seeds:
  the spread of k and rho against the Cramer-Rao bound (the mean one-sigma error the fit
  reports from its Jacobian, which is the bound for this Gaussian model).
- ``table2``: the physical synthetic table2 preset, fitted end to end by ``softshadow fit`` in
  a fresh process (cold and warm compilation cache), against its truth.
"""

from __future__ import annotations

import dataclasses
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

__all__ = ["bench_same_model", "bench_table2", "bench_fit"]


def bench_same_model(seeds: int = 20, k: float = 0.012, rho: float = 0.25, noise: float = 0.01,
                     max_samples_per_photo: int | None = None) -> dict:
    from data_synth import model_topdown_folder
    from fitting import FitOptions, fit_folder
    options = FitOptions(profiles=("disk",), blur=(False,), robust=False, sky_occlusion=False,
                         plots=False)  # the data were rendered without the sky term
    if max_samples_per_photo is not None:
        options = dataclasses.replace(options, max_samples_per_photo=int(max_samples_per_photo))
    ks, rhos, k_se, rho_se, secs, solve_secs, used = [], [], [], [], [], [], []
    with tempfile.TemporaryDirectory() as tmp:
        for seed in range(seeds):
            folder = model_topdown_folder(Path(tmp) / f"s{seed}", k, rho, noise, seed, group="g", time=None)
            (g,) = fit_folder(folder, options=options).groups
            ks.append(g.range_k)
            rhos.append(g.rho)
            k_se.append(g.range_stderr)
            rho_se.append(g.rho_stderr)
            secs.append(g.seconds)
            solve_secs.append(g.solve_seconds)
            used.append(g.n_samples)
    ks, rhos = np.array(ks), np.array(rhos)
    return {
        "truth": {"range_k": k, "rho": rho, "noise_sigma": noise, "seeds": seeds},
        "samples_used": int(np.median(used)),
        "range_k": {"mean": float(ks.mean()), "std": float(ks.std(ddof=1)),
                    "crb": float(np.mean(k_se)), "std_over_crb": float(ks.std(ddof=1) / np.mean(k_se)),
                    "bias_over_crb": float((ks.mean() - k) / np.mean(k_se))},
        "rho": {"mean": float(rhos.mean()), "std": float(rhos.std(ddof=1)),
                "crb": float(np.mean(rho_se)), "std_over_crb": float(rhos.std(ddof=1) / np.mean(rho_se)),
                "bias_over_crb": float((rhos.mean() - rho) / np.mean(rho_se))},
        "group_seconds_after_compile": {"median": float(np.median(secs[1:])),
                                        "first_with_compile": float(secs[0])},
        "solve_seconds_after_compile": {"median": float(np.median(solve_secs[1:])),
                                        "max": float(np.max(solve_secs[1:]))},
    }


def _fit_cli_seconds(folder: Path, out: Path, cache: Path) -> float:
    """Wall time of ``softshadow fit`` in a fresh process (imports and compilation included)."""
    env = dict(os.environ, SOFTSHADOW_JAX_CACHE=str(cache))
    t = time.perf_counter()
    subprocess.run([sys.executable, "-m", "softshadow_cli", "fit", str(folder), "--out", str(out), "--force"],
                   check=True, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    return time.perf_counter() - t


def bench_table2(size=(1600, 1200), seed: int = 0) -> dict:
    """The physical table2 preset fitted by ``softshadow fit`` in a fresh process: wall time
    with an empty JAX compilation cache (``cold``) and with the cache the first run filled
    (``warm``), and each group's errors against the truth."""
    from data_synth import synthesize

    out = {}
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp) / "table2"
        t0 = time.perf_counter()
        synthesize(folder, preset="table2", seed=seed, size=size, progress=False)
        out["synth_seconds"] = round(time.perf_counter() - t0, 2)
        truth = json.loads((folder / "truth.json").read_text())
        cache = Path(tmp) / "jax-cache"
        out["fit_seconds_wall"] = {
            "cold": round(_fit_cli_seconds(folder, Path(tmp) / "out", cache), 2),
            "warm": round(_fit_cli_seconds(folder, Path(tmp) / "out", cache), 2)}
        groups = json.loads((Path(tmp) / "out" / "results.json").read_text())["groups"]
    by_photos = {tuple(sorted(g["photos"])): g for g in groups}
    rows = []
    for t in truth["groups"]:
        g = by_photos.get(tuple(sorted(t["photos"])))
        if g is None or g.get("range_k") is None:
            rows.append({"label": t["label"], "error": "not fitted"})
            continue
        rows.append({"label": t["label"], "range_k": g["range_k"], "truth_range_k": t["range_k"],
                     "k_rel_error": (g["range_k"] - t["range_k"]) / t["range_k"],
                     "rho": g["rho"], "truth_rho": t["rho"], "rho_abs_error": g["rho"] - t["rho"],
                     "range_stderr": g["range_stderr"], "rho_stderr": g["rho_stderr"],
                     "group_seconds": g["seconds"], "solve_seconds": g.get("solve_seconds")})
    out["size"] = list(size)
    out["groups"] = rows
    return out


def bench_fit(quick: bool = False) -> dict:
    return {"same_model": bench_same_model(seeds=6 if quick else 40),
            "table2": bench_table2(size=(800, 600) if quick else (1600, 1200))}

