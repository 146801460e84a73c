"""The differentiable part: penumbra alpha at receiver points from their silhouette edge (JAX).

For a receiver point x governed by silhouette edge (a, b) with unit tangent t,
under light direction L (unit), let

    c = |t x L|,   n = sign * (t x L) / c   (outward, perpendicular to t and L),
    m = (L - (L.t) t) / c                   (the light direction across the edge),
    T(x) = ((x - a) . n) / ((x - a) . m),

the tangent of the angle of x around the edge line, measured from the hard
shadow's boundary plane (T > 0 outside). The expanded and contracted volumes'
boundary planes contain the edge and the light directions L + k N and L - k N:

- ``edge`` rule (N = n): T_out = T_in = k / c;
- ``paper`` rule (N = normalize(N1 + N2), the seed's):
  T_out = k (N.n) / (c + k N.m), T_in = k (N.n) / (c - k N.m).

The normalised penumbra coordinate u = (2 T - T_out + T_in) / (T_out + T_in)
is +1 on the outer (expanded) silhouette and -1 on the inner one, and the
profile maps it to alpha: ``linear`` (the seed's step 5, alpha = (1 - u) / 2)
or ``disk`` (the occluded fraction of a uniform disk behind a straight edge).
On a plane receiver T is linear in ground distance to first order in k, so
alpha is the seed's linear ramp between the two silhouettes.

Every division is guarded (double-where) so values and gradients stay finite
at k = 0, at points on the edge line, and for points upstream of the edge.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
from jaxtyping import Array, Float, Int

__all__ = ["PROFILES", "RULES", "penumbra_coordinate", "profile_alpha", "edge_alpha",
           "occluded_disk_fraction", "shade"]

PROFILES = ("linear", "disk")
RULES = ("edge", "paper")

_K_MIN = 1e-9       # below this the ramp is a step; keeps 1/k finite
_TINY = 1e-30


def _safe_div(num, den, eps):
    """num / den where |den| > eps, else num / eps with den's sign (double-where, finite gradients)."""
    ok = jnp.abs(den) > eps
    den_safe = jnp.where(ok, den, jnp.where(den < 0, -eps, eps))
    return num / den_safe


def _norm(v, eps=_TINY):
    sq = jnp.sum(v * v, axis=-1)
    ok = sq > eps
    return jnp.where(ok, jnp.sqrt(jnp.where(ok, sq, 1.0)), 0.0)


@jax.custom_jvp
def occluded_disk_fraction(u):
    """Fraction of a uniform disk hidden by a straight edge, u in [-1, 1] (1: none hidden).

    f(u) = (acos u - u sqrt(1 - u^2)) / pi, clamped outside [-1, 1]; its
    derivative -2 sqrt(1 - u^2) / pi is finite everywhere (custom JVP).
    """
    uc = jnp.clip(u, -1.0, 1.0)
    return (jnp.arccos(uc) - uc * jnp.sqrt(jnp.maximum(1.0 - uc * uc, 0.0))) / jnp.pi


@occluded_disk_fraction.defjvp
def _occluded_disk_fraction_jvp(primals, tangents):
    (u,), (du,) = primals, tangents
    uc = jnp.clip(u, -1.0, 1.0)
    slope = -2.0 * jnp.sqrt(jnp.maximum(1.0 - uc * uc, 0.0)) / jnp.pi
    return occluded_disk_fraction(u), slope * du


def profile_alpha(u, profile: str = "linear"):
    """Alpha (0 lit, 1 umbra) from the normalised penumbra coordinate u (+1 outer, -1 inner)."""
    if profile == "linear":
        return jnp.clip(0.5 * (1.0 - u), 0.0, 1.0)
    if profile == "disk":
        return occluded_disk_fraction(u)
    raise ValueError(f"unknown penumbra profile {profile!r}; choose one of {PROFILES}")


def penumbra_coordinate(points: Float[Array, "n 3"], a: Float[Array, "n 3"], b: Float[Array, "n 3"],
                        outward_sign: Float[Array, " n"], light: Float[Array, "3"], range_k,
                        rule: str = "edge", paper_normal: Float[Array, "n 3"] | None = None):
    """Normalised penumbra coordinate u (n,) of each point against its own edge (a, b).

    u = +1 on the expanded silhouette, -1 on the contracted one, |u| > 1 outside
    the penumbra (saturated to +-1e6 upstream of the edge or for k = 0).
    """
    t = b - a
    t = t / jnp.maximum(_norm(t), 1e-12)[:, None]
    cvec = jnp.cross(t, light)
    c = jnp.maximum(_norm(cvec), 1e-12)
    n = outward_sign[:, None] * cvec / c[:, None]
    m = (light - jnp.sum(light * t, -1, keepdims=True) * t) / c[:, None]
    w = points - a
    num = jnp.sum(w * n, -1)
    den = jnp.sum(w * m, -1)
    scale = _norm(w) + 1e-12
    k = jnp.maximum(jnp.asarray(range_k, dtype=points.dtype), _K_MIN)
    if rule == "edge":
        t_out = k / c
        t_in = t_out
    elif rule == "paper":
        if paper_normal is None:
            raise ValueError("the paper rule needs per-edge normals")
        nn = jnp.sum(paper_normal * n, -1)
        nm = jnp.sum(paper_normal * m, -1)
        # N leans outward at a silhouette; guard the rare edge where it does not.
        nn = jnp.maximum(nn, 1e-6)
        t_out = k * nn / jnp.maximum(c + k * nm, 1e-9)
        t_in = k * nn / jnp.maximum(c - k * nm, 1e-9)
    else:
        raise ValueError(f"unknown expansion rule {rule!r}; choose one of {RULES}")
    upstream = den <= 1e-9 * scale
    tan_x = _safe_div(num, den, 1e-9 * scale)
    u = (2.0 * tan_x - t_out + t_in) / (t_out + t_in)
    saturated = jnp.where(num > 0, 1e6, jnp.where(num < 0, -1e6, 0.0))
    return jnp.where(upstream, saturated, jnp.clip(u, -1e6, 1e6))


def edge_alpha(points, edge_ids: Int[Array, " n"], edge_vertices_world: Float[Array, "s 2 3"],
               outward_sign: Float[Array, " s"], light, range_k, rule: str = "edge",
               profile: str = "linear", paper_normal_world: Float[Array, "s 3"] | None = None):
    """Alpha (n,) at points (n, 3), each against silhouette edge ``edge_ids[i]``."""
    ev = edge_vertices_world[edge_ids]
    pn = None if paper_normal_world is None else paper_normal_world[edge_ids]
    u = penumbra_coordinate(points, ev[:, 0], ev[:, 1], outward_sign[edge_ids], light, range_k,
                            rule, pn)
    return profile_alpha(u, profile)


def shade(alpha, rho):
    """Shadow factor 1 - alpha (1 - rho): irradiance over lit irradiance, in linear units."""
    return 1.0 - alpha * (1.0 - rho)
