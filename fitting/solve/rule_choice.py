"""Which rule draws a group's penumbra (``FitOptions.rule``): the ``edge`` rule's ramp about the
nearest silhouette edge, or the ``wedge`` rule's hidden fraction of the sun's disk, chosen per group
when the rule is ``auto``.

The ``wedge`` rule is right where silhouette edges crowd (gaps narrower than the penumbra,
overlapping parts, corners) and the same as the ``edge`` rule along a lone straight edge, at a
higher price. So the group is fitted with the ``edge`` rule first; at its solution (k, rho, sun,
pose, blur, the photos' levels) the ``wedge`` rule's shading is computed at the fit's own samples,
and one Gauss-Newton step with the edge fit's Jacobian from the edge rule's residuals to the
wedge rule's gives, to first order, how far the wedge rule would move k and rho. When the larger
move, in the edge fit's standard errors (``RuleChoice.criterion``), exceeds ``WEDGE_THRESHOLD``, the
group is refitted with the ``wedge`` rule from the edge fit's solution; else the edge fit is kept:
the simple rule is as good as the photos can tell. The reason line also gives the two rules' RMS
difference in the penumbra and the photos' noise on the lit ground.
"""

from __future__ import annotations

from typing import Literal, NamedTuple

import equinox as eqx
import numpy as np
from scipy.stats import median_abs_deviation

from softshadow import Pose, SoftShadowModel, Sun
from softshadow.internal import PointPlan, bucket_size, concatenate_plans

from .options import sampling_rule
from .model import FitConfig, FitParams, GroupArrays, Prediction, k_rho_slopes, predict, pseudo_huber
from ..photos.views import PhotoView
from ..samples.photo_samples import PhotoSamples

#: Singular values of the Jacobian below this fraction of the largest count as zero (``group.COV_RCOND``).
COV_RCOND = 1e-6

__all__ = ["WEDGE_THRESHOLD", "ALPHA_EDGE", "RuleChoice", "sampling_rule", "wedge_plan",
           "choose_rule", "wedge_footprints", "wedge_unavailable"]

#: The ``wedge`` rule is chosen when it moves k or rho by more than this many of the edge fit's
#: standard errors (``choose_rule``; the values measured on the pillar and the dragon are in
#: docs/fitting.md).
WEDGE_THRESHOLD = 1.0
#: A sample counts as in the penumbra when either rule's alpha lies within this of neither 0 nor 1.
ALPHA_EDGE = 1e-3
#: Fewer lit samples than this: the noise is the spread of all the edge fit's residuals.
_MIN_LIT = 30


class RuleChoice(NamedTuple):
    """The rule a group was fitted with and why.

    rule: "edge", "paper" or "wedge"; criterion: the larger of the moves of k and rho the wedge
    rule asks for, in their standard errors (None when not measured); k_move, rho_move: those
    moves; difference_rms: the RMS difference of the two rules' shading (relative to the lit
    level) over the n_penumbra samples either puts in the penumbra; noise: the photos' noise on
    the lit samples (same units); reason: one line.
    """

    rule: Literal["edge", "paper", "wedge"]
    criterion: float | None = None
    k_move: float | None = None
    rho_move: float | None = None
    difference_rms: float | None = None
    noise: float | None = None
    n_penumbra: int = 0
    reason: str = ""


def wedge_footprints(samples: list[PhotoSamples], blur_variance: np.ndarray, size: int) -> np.ndarray:
    """Each sample's footprint (size, 2, 3) for the wedge rule's means: its pixel's two sides
    (``PhotoSamples.jac``) widened by sqrt(1 + 12 b^2), b^2 its photo's camera blur variance
    (blur_variance (P,), px^2; negative values count as 0); padding rows repeat the first."""
    parts = [np.swapaxes(s.jac, 1, 2) * np.sqrt(1.0 + 12.0 * max(float(b), 0.0))
             for s, b in zip(samples, blur_variance)]
    axes = np.concatenate(parts)
    return np.concatenate([axes, np.broadcast_to(axes[:1], (size - len(axes), 2, 3))])


def wedge_plan(model: SoftShadowModel, pose: Pose, samples: list[PhotoSamples], views: list[PhotoView],
               range_k_max: float, axes: np.ndarray) -> PointPlan | None:
    """The ``wedge`` rule's plan at every photo's samples (each under its own sun) over the
    footprints axes (size, 2, 3) (``wedge_footprints``), one plan of ``size`` points as
    ``GroupArrays`` pads them; its pairs and crossings padded to power-of-two buckets (few
    compiled shapes). On the ground plane the plan is made on z = 0; on a range image or a mesh
    at the receiver's points with their normals (``PhotoSamples.normals``: a face turned from the
    sun is in attached shadow, and the layers in front of a point are found by ray casting).
    None when ``wedge_unavailable`` gives a reason."""
    if wedge_unavailable(samples, views) is not None:
        return None
    wedge_model = model.with_options(rule="wedge")
    counts = [len(s.observed) for s in samples]
    starts = np.cumsum([0] + counts)
    plans = [wedge_model.plan_points(Sun(float(v.sun_azimuth_deg), float(v.sun_elevation_deg)), pose, s.ground,
                                     range_k_max=range_k_max * 1.5, pixel_axes=axes[a:a + len(s.observed)],
                                     normals=s.normals)
             for s, v, a in zip(samples, views, starts)]
    pairs = sum(int(np.count_nonzero(np.asarray(p.wedge.pair_point) >= 0)) for p in plans if p.wedge is not None)
    cross = sum(int(np.asarray(p.wedge.cross).shape[0]) for p in plans if p.wedge is not None)
    edges = sum(int(np.asarray(p.edges.outward_sign).shape[0]) for p in plans)
    return concatenate_plans(plans, counts, pad_to=len(axes), edge_pad_to=bucket_size(edges, 256),
                             pairs_to=bucket_size(pairs, 1024), cross_to=bucket_size(cross, 256))


def _receiver_kind(view: PhotoView) -> str:
    return "plane" if view.receiver is None else str(getattr(view.receiver, "kind", "plane"))


def wedge_unavailable(samples: list[PhotoSamples], views: list[PhotoView]) -> str | None:
    """Why the ``wedge`` rule cannot be planned at these samples (one line), or None when it can:
    on the ground plane always; on a range image or a mesh when the samples carry the receiver's
    normals (``fitting.samples.receiver`` gives them)."""
    for s, v in zip(samples, views):
        kind = _receiver_kind(v)
        if kind != "plane" and (s.normals is None or len(s.normals) != len(s.observed)):
            return f"{v.name}: the samples on its {kind} receiver carry no normals, which the wedge rule's plan needs"
    return None


@eqx.filter_jit
def _values_alpha(params: FitParams, group: GroupArrays, pose: Pose, config: FitConfig):
    pred = predict(params, group, pose, config)
    return pred.values, pred.alpha


def _transformed(r: np.ndarray, delta: float) -> np.ndarray:
    """The residuals the solver minimises: ``pseudo_huber``'s (delta 0: plain)."""
    return np.asarray(pseudo_huber(r, delta), np.float64) if delta > 0 else r


def choose_rule(params: FitParams, config: FitConfig, group: GroupArrays, pose: Pose, edge: Prediction,
                jacobian: np.ndarray, cov: np.ndarray, n: int) -> RuleChoice:
    """``RuleChoice`` for a group fitted with the ``edge`` rule (module docstring).

    params, config: the edge fit's solution and configuration; group: its arrays, with the
    ``wedge_plan``; edge: the edge fit's prediction at the solution (NumPy, padded); jacobian
    (n_padded, p), cov (p, p): the solver's residual Jacobian and the covariance at that solution
    (``FitParams.layout`` order); n: the real samples (the rest is padding)."""
    wedge_config = FitConfig(config.fit_blur, config.fit_sun, config.huber_delta, config.profile, "wedge")
    values_w, alpha_w = (np.asarray(x, np.float64) for x in _values_alpha(params, group, pose, wedge_config))
    values_e, alpha_e = np.asarray(edge.values, np.float64), np.asarray(edge.alpha, np.float64)
    photo = np.asarray(group.photo)
    scale = np.asarray(group.scale)[photo]
    weight = np.asarray(group.weight)
    observed = np.asarray(group.observed)
    # The solver's residuals under either rule at the edge fit's solution; one Gauss-Newton step
    # (the edge fit's Jacobian) from there gives the parameters' move the wedge rule asks for.
    delta = float(config.huber_delta)
    r_e = _transformed(weight * (observed - values_e) / scale, delta)
    r_w = _transformed(weight * (observed - values_w) / scale, delta)
    u, sv, vt = np.linalg.svd(np.asarray(jacobian, np.float64), full_matrices=False)
    keep = sv > COV_RCOND * (sv[0] if len(sv) else 0.0)
    step = -(vt.T * np.where(keep, 1.0 / np.where(keep, sv, 1.0), 0.0)) @ (u.T @ (r_w - r_e))
    lay = FitParams.layout(params.n_photos)
    ik, ir = lay["raw_k"].start, lay["raw_rho"].start
    dk, drho = k_rho_slopes(params.raw_k, params.raw_rho)
    se_k, se_rho = np.sqrt(max(cov[ik, ik], 0.0)) * dk, np.sqrt(max(cov[ir, ir], 0.0)) * drho
    k_move, rho_move = step[ik] * dk, step[ir] * drho
    criterion = float(max(abs(k_move) / max(se_k, 1e-300), abs(rho_move) / max(se_rho, 1e-300)))
    # For the reason line: the rules' difference in the penumbra and the photos' noise on lit ground.
    diff = ((values_w - values_e) / scale)[:n]
    lo, hi = np.minimum(alpha_e, alpha_w)[:n], np.maximum(alpha_e, alpha_w)[:n]
    penumbra = (hi > ALPHA_EDGE) & (lo < 1.0 - ALPHA_EDGE)
    lit = hi <= ALPHA_EDGE
    residual = ((observed - values_e) / scale)[:n]
    sample = residual[lit] if np.count_nonzero(lit) >= _MIN_LIT else residual
    noise = float(median_abs_deviation(sample, scale="normal")) if len(sample) else 0.0
    rms = float(np.sqrt(np.mean(diff[penumbra] ** 2))) if penumbra.any() else 0.0
    rule: Literal["edge", "wedge"] = "wedge" if criterion > WEDGE_THRESHOLD else "edge"
    reason = (f"the wedge rule moves k by {k_move:+.3g} ({k_move / max(se_k, 1e-300):+.2f} se) and rho by "
              f"{rho_move:+.3g} ({rho_move / max(se_rho, 1e-300):+.2f} se), "
              f"{'more than' if rule == 'wedge' else 'at most'} {WEDGE_THRESHOLD:g} se; the rules' shading differs by "
              f"{rms:.4f} RMS over {int(penumbra.sum())} penumbra samples, noise {noise:.4f}")
    return RuleChoice(rule, criterion, float(k_move), float(rho_move), rms, noise, int(penumbra.sum()), reason)
