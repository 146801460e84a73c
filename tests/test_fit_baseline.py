"""Baseline 6: the fitter's own problem (``fitting.group_problem``) solved by SciPy's
finite-difference least squares lands where the fitter's autodiff solve lands."""

from __future__ import annotations

import numpy as np
import pytest

from fitting import FitOptions, fit_group, group_problem
from benchmarks.fit_baseline import TRUTH_K, compare_solvers, same_model_views


@pytest.fixture(scope="module")
def problem_and_views(tmp_path_factory):
    model, pose, views = same_model_views(tmp_path_factory.mktemp("baseline"), n_photos=1, seed=0)
    options = FitOptions(profiles=("disk",), blur=(False,), robust=False, sky_occlusion=False, plots=False,
                         max_samples_per_photo=300)
    return group_problem(model, pose, views, options), (model, pose, views, options)


def test_group_problem_is_the_fitters_problem(problem_and_views):
    problem, (model, pose, views, options) = problem_and_views
    assert problem.n_photos == 1 and problem.n_samples <= 300 and len(problem.x0) == 9
    r0 = problem.residuals(problem.x0)
    assert r0.dtype == np.float64 and np.all(r0[problem.n_samples:] == 0)  # padding rows
    sol = problem.solve()
    assert sol.converged and np.sum(problem.residuals(sol.x) ** 2) < np.sum(r0 ** 2)
    # fit_group solves the same plain problem (then once more with the same configuration).
    g = fit_group(model, pose, views, "g", None, options)
    k, rho = problem.k_rho(sol.x)
    assert k == pytest.approx(g.range_k, rel=2e-3) and rho == pytest.approx(g.rho, abs=1e-3)


def test_finite_differences_reach_the_autodiff_solution(problem_and_views):
    problem, _ = problem_and_views
    out = compare_solvers(problem, TRUTH_K, 0.25, repeats=1)
    ad, fd = out["autodiff"], out["finite_differences"]
    assert fd["converged"] and fd["residual_evaluations"] >= 2
    assert fd["range_k"] == pytest.approx(ad["range_k"], rel=1e-3)
    assert fd["rho"] == pytest.approx(ad["rho"], abs=1e-4)
    assert abs(ad["error"]["k_rel"]) < 0.2 and ad["median_ms"] > 0 and fd["median_ms"] > 0
    assert out["time_ratio_fd_over_autodiff"] == pytest.approx(fd["median_ms"] / ad["median_ms"])
