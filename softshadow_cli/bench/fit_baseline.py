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


def bench_fit_baseline(photos_per_group=(1, 3), seeds: int = 3, max_samples_per_photo: int = 1300,
                       repeats: int = 3) -> dict:
    """Both solvers on ``seeds`` groups of each size in ``photos_per_group``; per group and summed
    up (medians over the groups, and the RMS of the k and rho errors)."""
    from fitting import FitOptions, group_problem
    options = FitOptions(profiles=("disk",), blur=(False,), robust=False, sky_occlusion=False, plots=False,
                         max_samples_per_photo=int(max_samples_per_photo))
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for n in photos_per_group:
            for seed in range(seeds):
                model, pose, views = same_model_views(Path(tmp), n, seed)
                problem = group_problem(model, pose, views, options)
                rows.append({"photos": n, "seed": seed, "samples": problem.n_samples,
                             "parameters": int(len(problem.x0)),
                             **compare_solvers(problem, TRUTH_K, TRUTH_RHO, repeats)})
    summary = {}
    for n in photos_per_group:
        sel = [r for r in rows if r["photos"] == n]
        summary[str(n)] = {
            solver: {"median_ms": float(np.median([r[solver]["median_ms"] for r in sel])),
                     "k_rel_rms": float(np.sqrt(np.mean([r[solver]["error"]["k_rel"] ** 2 for r in sel]))),
                     "rho_abs_rms": float(np.sqrt(np.mean([r[solver]["error"]["rho_abs"] ** 2 for r in sel])))}
            for solver in ("autodiff", "finite_differences")}
        summary[str(n)]["time_ratio_fd_over_autodiff"] = float(np.median([r["time_ratio_fd_over_autodiff"]
                                                                           for r in sel]))
        summary[str(n)]["k_fd_minus_autodiff_max_rel"] = float(max(
            abs(r["finite_differences"]["range_k"] - r["autodiff"]["range_k"]) / TRUTH_K for r in sel))
    return {"truth": {"range_k": TRUTH_K, "rho": TRUTH_RHO, "noise_sigma": NOISE},
            "max_samples_per_photo": int(max_samples_per_photo), "groups": rows, "by_photos": summary}
