"""One group's least-squares problem as plain vector functions, for solvers other than the fitter's.

``group_problem`` builds what ``fit_group``'s first (plain) solve works on, with the fitter's own
steps (``sample_views``, ``initial_params``, the coarse k grid of ``plain_start``): the start
vector x0 (p,) in ``FitParams.layout`` order, and the residuals r(x) (n,) of ``model.residuals``
(one compiled float64 function). ``solve`` runs the fitter's own Levenberg-Marquardt (optimistix,
autodiff Jacobian) from x0 on the same residuals, so another solver (for instance SciPy's
``least_squares`` with finite differences) can be compared with it on one problem.
"""

from __future__ import annotations

import dataclasses
from typing import NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from softshadow import Pose, SoftShadowModel

from .model import FitParams, residuals
from .group import (FitOptions, _group_arrays, _k_np, _prepare, _rho_np, _solve, initial_params, plain_config,
                    sample_views, start_grid)
from ..photos.views import PhotoView

__all__ = ["GroupProblem", "SolveOutcome", "group_problem"]


class SolveOutcome(NamedTuple):
    """x (p,) at the solution, the solver's step count and whether it converged."""

    x: np.ndarray
    steps: int
    converged: bool


@eqx.filter_jit
def _residual_vector(x, args, n_photos: int):
    return residuals(FitParams.from_vector(x, n_photos), args)


@eqx.filter_jit
def _start(params: FitParams, raw_ks, args):
    group, pose, config = args
    return _prepare(params, raw_ks, group, pose, config)


@dataclasses.dataclass
class GroupProblem:
    """The plain least-squares problem of one group (float64).

    x0 (p,): the start; n_photos; n_samples: the samples used (the residual vector is padded
    to a bucket size with zero rows); max_steps: the fitter's step limit.
    """

    x0: np.ndarray
    n_photos: int
    n_samples: int
    max_steps: int
    _args: tuple

    def residuals(self, x: np.ndarray) -> np.ndarray:
        """r(x) (n,) of ``fitting.solve.model.residuals`` for x (p,) in ``FitParams.layout`` order."""
        with jax.enable_x64(True):
            return np.asarray(_residual_vector(jnp.asarray(x, jnp.float64), self._args, self.n_photos))

    def solve(self) -> SolveOutcome:
        """The fitter's own solve (``fitting.solve.group``: optimistix Levenberg-Marquardt with the
        autodiff Jacobian, and the Jacobian at the solution the errors come from) from x0."""
        with jax.enable_x64(True):
            params = FitParams.from_vector(jnp.asarray(self.x0, jnp.float64), self.n_photos)
            sol = _solve(params, self._args, self.max_steps, jnp.zeros(9), jnp.asarray(False))
            return SolveOutcome(np.asarray(sol.params.vector()), int(sol.steps), bool(sol.converged))

    def k_rho(self, x: np.ndarray) -> tuple[float, float]:
        """(k, rho) of a parameter vector x (p,)."""
        lay = FitParams.layout(self.n_photos)
        return _k_np(x[lay["raw_k"]][0]), _rho_np(x[lay["raw_rho"]][0])


def group_problem(model: SoftShadowModel, pose: Pose, views: list[PhotoView],
                  options: FitOptions | None = None) -> GroupProblem:
    """The plain problem ``fit_group`` solves first for these views: the first of
    ``options.profiles``, blur fitted when ``options.blur`` allows it, no robust loss, the sun
    fitted when a view's sun is; k starts at the best of the fitter's coarse grid.

    Raises ``NoShadowInView`` when no view has a shadow to sample."""
    from ..samples.photo_samples import NoShadowInView
    options = options or FitOptions()
    with jax.enable_x64(True):
        samples, used, warnings = sample_views(model, pose, views, options)
        if not samples:
            raise NoShadowInView("; ".join(warnings))
        arrays = _group_arrays(samples, used)
        base, _ = initial_params(samples)
        fit_sun = any(v.sun_source == "fitted" for v in used)
        config = plain_config(options, fit_sun)
        grad_t_pixel, raw_k = _start(base, start_grid(options), (arrays, pose, config))
        arrays = dataclasses.replace(arrays, grad_t_pixel=grad_t_pixel)
        x0 = np.asarray(dataclasses.replace(base, raw_k=raw_k).vector())
    return GroupProblem(x0, len(samples), sum(len(s.observed) for s in samples), options.max_steps,
                        (arrays, pose, config))
