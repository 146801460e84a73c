"""Baseline 6: the same fit without autodiff, and the fit's cost against photos per group.

Each group is the pillar rendered top-down by the project's own model (disk profile, pixels
integrating 4 x 4 point samples, Gaussian noise; ``data_synth.model_topdown_folder``), one noise
seed per photo. ``fitting.group_problem`` gives the fitter's own plain least-squares problem for the
group (its samples, start and residual function); on it, in the same process:

- ``autodiff``: the fitter's own solve (optimistix Levenberg-Marquardt, Jacobian by autodiff,
  then the Jacobian at the solution the errors come from);
- ``finite_differences``: ``scipy.optimize.least_squares`` (trust region reflective, its default
  tolerances) on the same residual function, Jacobian by 2-point finite differences.

Both are timed after compilation (median of repeats) and their k and rho compared with the truth.
"""

from __future__ import annotations

import tempfile
from pathlib import Path

import numpy as np

from .measure import timed

__all__ = ["same_model_views", "compare_solvers", "bench_fit_baseline"]

TRUTH_K, TRUTH_RHO, NOISE = 0.012, 0.25, 0.01


def same_model_views(folder: Path, n_photos: int, seed: int, k: float = TRUTH_K, rho: float = TRUTH_RHO,
                     noise: float = NOISE):
    """(model, pose, views): ``n_photos`` same-model top-down photos of one moment (noise seeds
    ``seed * 100 + i``), read back as the fitter reads them."""
    from data_synth import model_topdown_folder
    from fitting import PhotoView, read_photo
    from scene import load_scene
    from softshadow import Pose, SoftShadowModel
    views = []
    for i in range(n_photos):
        sub = model_topdown_folder(Path(folder) / f"p{seed}_{i}", k, rho, noise, seed * 100 + i, group="g", time=None)
        scene = load_scene(sub / "scene.toml")
        photo = read_photo(sub / "top.png")
        spec = scene.photo("top.png")
        h, w = photo.gray.shape
        views.append(PhotoView(f"top{i}.png", photo.gray, photo.excluded, grid=scene.camera_for("top.png").grid(w, h),
                               sun_azimuth_deg=spec.sun_azimuth_deg, sun_elevation_deg=spec.sun_elevation_deg,
                               sun_source="given"))
    return SoftShadowModel.from_mesh("pillar"), Pose(), views


def compare_solvers(problem, k_truth: float, rho_truth: float, repeats: int = 3) -> dict:
    """Time and error of the autodiff solve and of SciPy's finite-difference solve of one problem."""
    from scipy.optimize import least_squares

    def scipy_solve():
        return least_squares(problem.residuals, problem.x0, jac="2-point", method="trf",
                             max_nfev=100 * (len(problem.x0) + 1))

    ad = problem.solve()
    fd = scipy_solve()  # also compiles the residual function
    out = {}
    for name, x, timing, extra in (
            ("autodiff", ad.x, timed(problem.solve, repeats, warmup=0),
             {"solver": "optimistix LevenbergMarquardt, autodiff Jacobian", "steps": ad.steps,
              "converged": ad.converged}),
            ("finite_differences", fd.x, timed(scipy_solve, repeats, warmup=0),
             {"solver": "scipy.optimize.least_squares trf, 2-point Jacobian", "residual_evaluations": int(fd.nfev),
              "jacobian_evaluations": int(fd.njev), "converged": bool(fd.success), "status": int(fd.status)})):
        k, rho = problem.k_rho(np.asarray(x))
        r = problem.residuals(np.asarray(x))
        out[name] = {**timing, **extra, "range_k": k, "rho": rho,
                     "error": {"k_rel": (k - k_truth) / k_truth, "rho_abs": rho - rho_truth,
                               "rms_residual": float(np.sqrt(np.sum(r ** 2) / problem.n_samples))}}
    out["time_ratio_fd_over_autodiff"] = out["finite_differences"]["median_ms"] / out["autodiff"]["median_ms"]
    return out


def _summary(rows: list[dict]) -> dict:
    out = {solver: {"median_ms": float(np.median([r[solver]["median_ms"] for r in rows])),
                    "k_rel_rms": float(np.sqrt(np.mean([r[solver]["error"]["k_rel"] ** 2 for r in rows]))),
                    "rho_abs_rms": float(np.sqrt(np.mean([r[solver]["error"]["rho_abs"] ** 2 for r in rows]))),
                    "peak_extra_mb": max((r[solver]["peak_extra_mb"] or 0.0) for r in rows)}
           for solver in ("autodiff", "finite_differences")}
    out["samples"] = int(np.median([r["samples"] for r in rows]))
    out["parameters"] = rows[0]["parameters"]
    out["groups"] = len(rows)
    out["time_ratio_fd_over_autodiff"] = float(np.median([r["time_ratio_fd_over_autodiff"] for r in rows]))
    out["k_fd_minus_autodiff_max_rel"] = float(max(
        abs(r["finite_differences"]["range_k"] - r["autodiff"]["range_k"]) / TRUTH_K for r in rows))
    return out


def bench_fit_baseline(photos_per_group=(1, 2, 4, 8), caps=(150, 400, 1300, 4000), seeds: int = 3,
                       repeats: int = 3, cap_for_photos: int | None = None) -> dict:
    """Both solvers on ``seeds`` groups of each size in ``photos_per_group`` (samples per photo
    capped at ``cap_for_photos``, default the cap nearest the fitter's default), and on
    one-photo groups at each cap in ``caps``. Per group, summed up per size (medians over the
    groups, RMS of the k and rho errors), and the log-log slopes of time against photos per group
    and against samples."""
    from fitting import FitOptions, group_problem
    from .scaling import loglog_slope
    default_cap = FitOptions().max_samples_per_photo
    cap_for_photos = cap_for_photos or min(caps, key=lambda c: abs(c - default_cap))
    runs = sorted({(n, cap_for_photos) for n in photos_per_group} | {(1, c) for c in caps})
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for n, cap in runs:
            options = FitOptions(profiles=("disk",), blur=(False,), robust=False, sky_occlusion=False, plots=False,
                                 max_samples_per_photo=int(cap))
            for seed in range(seeds):
                model, pose, views = same_model_views(Path(tmp), n, seed)
                problem = group_problem(model, pose, views, options)
                rows.append({"photos": n, "cap": int(cap), "seed": seed, "samples": problem.n_samples,
                             "parameters": int(len(problem.x0)),
                             **compare_solvers(problem, TRUTH_K, TRUTH_RHO, repeats)})
    by_photos = {str(n): _summary([r for r in rows if r["photos"] == n and r["cap"] == cap_for_photos])
                 for n in photos_per_group}
    by_cap = {str(c): _summary([r for r in rows if r["photos"] == 1 and r["cap"] == c]) for c in caps}

    def slope(summary, x_key):
        return {solver: loglog_slope([v[x_key] if x_key != "photos" else int(n) for n, v in summary.items()],
                                     [v[solver]["median_ms"] for v in summary.values()])
                for solver in ("autodiff", "finite_differences")}

    return {"truth": {"range_k": TRUTH_K, "rho": TRUTH_RHO, "noise_sigma": NOISE},
            "cap_for_photos": int(cap_for_photos), "groups": rows, "by_photos": by_photos, "by_cap": by_cap,
            "slope_vs_photos": slope(by_photos, "photos"), "slope_vs_samples": slope(by_cap, "samples")}
