"""Evaluating a plan: alpha and the penumbra coordinate at the plan's points (JAX).

The plan (``softshadow.plan``, NumPy) fixed the discrete choices; here the
chosen edges are posed and lit by the (possibly traced) pose and sun, and the
penumbra formula of ``softshadow.penumbra`` runs on them. Differentiable in
k, the sun angles and the pose while the plan's choices hold.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
from jaxtyping import Array, Float

from .params import Pose, Sun
from .penumbra import Profile, Rule, edge_alpha, edge_coordinate, footprint_bump
from .plan import PointPlan
from .wedge import pixel_mean_alpha, wedge_alpha

__all__ = ["plan_alpha", "plan_alpha_jit", "plan_coordinate", "plan_coordinate_light"]


def _as_jax(plan: PointPlan) -> PointPlan:
    """The plan's NumPy leaves as JAX arrays (a no-op under jit, where they are already traced),
    so that traced indices can gather from them."""
    return jax.tree_util.tree_map(jnp.asarray, plan)


def plan_alpha(points: Float[Array, "n 3"], plan: PointPlan, pose: Pose, sun: Sun, range_k,
               rule: Rule = "edge", profile: Profile = "linear",
               pixel_axes: Float[Array, "*n 2 3"] | None = None, corners: bool = False) -> Float[Array, " n"]:
    """Alpha (n,) at the plan's points: the penumbra formula in bands, the hard shadow elsewhere.

    pixel_axes: (2, 3) or (n, 2, 3) offsets (m) across a pixel along its two sides: alpha
    is then the mean over each pixel's footprint, else the value at the point. With the plan's
    pixel pieces (``PointPlan.wedge``, planned with the pixels) the mean is the hard shadow's
    exact area in the pixel plus the chosen edge's penumbra over it (``footprint_bump``);
    without, the chosen edge's profile over it (``footprint_profile_alpha``). corners: near a corner of the outline, the light's mass behind the
    corner's wedge (``corner_alpha``, when the plan holds the outline's neighbours), else
    the nearest edge's half-plane alone.
    """
    plan = _as_jax(plan)
    edges = plan.edges
    ev = pose.apply(edges.vertices_local)
    if rule == "wedge":
        alpha = _wedge_plan_alpha(points, plan, ev, sun.light, range_k, profile, pixel_axes)
        return jnp.where(plan.active, alpha, plan.hard)
    paper = pose.apply_direction(edges.paper_normal_local) if rule == "paper" else None
    if pixel_axes is not None and not corners and plan.wedge is not None and plan.wedge.pixel_side_start is not None:
        # The hard shadow's exact area in the pixel plus the chosen edge's penumbra over it: the
        # exact mean for one straight edge, and continuous where the nearest edge changes or the
        # ramp narrows below the pixel (at the foot of an object: a ground-level edge).
        u, du_a, du_b = edge_coordinate(points, plan.edge_id, ev, edges.outward_sign, sun.light, range_k,
                                        plan.hard, rule, paper, near_boundary=plan.near_boundary,
                                        pixel_axes=pixel_axes)
        alpha = pixel_mean_alpha(points, ev, sun.light, plan.wedge, pixel_axes) \
            + footprint_bump(u, du_a, du_b, profile)
        return jnp.where(plan.active, jnp.clip(alpha, 0.0, 1.0), plan.hard)
    alpha = edge_alpha(points, plan.edge_id, ev, edges.outward_sign, sun.light, range_k,
                       plan.hard, rule, profile, paper, near_boundary=plan.near_boundary,
                       pixel_axes=pixel_axes, neighbours=edges.neighbours if corners else None)
    return jnp.where(plan.active, alpha, plan.hard)


def _wedge_plan_alpha(points, plan: PointPlan, ev, light, range_k, profile, pixel_axes):
    """The ``wedge`` rule's alpha at the plan's points (``softshadow.wedge``)."""
    return wedge_alpha(points, ev, light, range_k, plan.wedge, profile, pixel_axes)


def plan_coordinate(points: Float[Array, "n 3"], plan: PointPlan, pose: Pose, sun: Sun, range_k,
                    rule: Rule = "edge", with_slope: bool = False):
    """Normalised penumbra coordinate u (n,) at the plan's points (+1 outer, -1 inner silhouette).

    Outside the penumbra bands u is +-1e6 from the hard shadow, so any profile
    gives alpha 0 or 1 there. Use with ``profile_alpha`` (possibly blurred).
    With ``with_slope`` also returns du/dT (see ``penumbra_coordinate``), 0 outside bands.
    """
    return plan_coordinate_light(points, plan, pose, sun.light, range_k, rule, with_slope)


def plan_coordinate_light(points: Float[Array, "n 3"], plan: PointPlan, pose: Pose,
                          light: Float[Array, "*n 3"], range_k, rule: Rule = "edge",
                          with_slope: bool = False):
    """``plan_coordinate`` with the light direction given directly, (3,) or one per point (n, 3)."""
    plan = _as_jax(plan)
    edges = plan.edges
    ev = pose.apply(edges.vertices_local)
    paper = pose.apply_direction(edges.paper_normal_local) if rule == "paper" else None
    u, slope = edge_coordinate(points, plan.edge_id, ev, edges.outward_sign, light, range_k,
                               plan.hard, rule, paper, with_slope=True,
                               near_boundary=plan.near_boundary)
    u = jnp.where(plan.active, u, jnp.where(plan.hard > 0.5, -1e6, 1e6))
    if with_slope:
        return u, jnp.where(plan.active, slope, 0.0)
    return u


plan_alpha_jit = jax.jit(plan_alpha, static_argnames=("rule", "profile", "corners"))
