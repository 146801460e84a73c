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

import functools
import typing
from typing import Literal, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float, Int

__all__ = ["Profile", "Rule", "PROFILES", "RULES", "penumbra_coordinate", "profile_alpha", "edge_alpha", "edge_coordinate",
           "profile_slope", "profile_integral", "footprint_profile_alpha", "footprint_bump",
           "occluded_disk_fraction", "corner_mass", "corner_alpha", "shade"]

#: The penumbra profiles: "linear" (the seed's ramp) or "disk" (the occluded fraction of a disk).
Profile = Literal["linear", "disk"]
#: The rules that draw the penumbra: "edge", "paper" (the expanded volume) or "wedge" (the sun's
#: hidden fraction, softshadow.wedge).
Rule = Literal["edge", "paper", "wedge"]
PROFILES: tuple[Profile, ...] = typing.get_args(Profile)
RULES: tuple[Rule, ...] = typing.get_args(Rule)

_K_MIN = 1e-9       # below this the ramp is a step; keeps 1/k finite
_TINY = 1e-30


def _safe_div(num, den, eps):
    """num / den where |den| > eps, else num / eps with den's sign (double-where, finite gradients)."""
    ok = jnp.abs(den) > eps
    den_safe = jnp.where(ok, den, jnp.where(den < 0, -eps, eps))
    return num / den_safe


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


def profile_alpha(u, profile: Profile = "linear"):
    """Alpha (0 lit, 1 umbra) from the normalised penumbra coordinate u (+1 outer, -1 inner)."""
    if profile == "linear":
        return jnp.clip(0.5 * (1.0 - u), 0.0, 1.0)
    if profile == "disk":
        return occluded_disk_fraction(u)
    raise ValueError(f"unknown penumbra profile {profile!r}; choose one of {PROFILES}")


def _split(v):
    """Components (x, y, z) of vectors (..., 3): the arithmetic below is per component
    (structure of arrays), which XLA vectorises far better than reductions over a size-3 axis."""
    return v[..., 0], v[..., 1], v[..., 2]


def _dot(u, v):
    return u[0] * v[0] + u[1] * v[1] + u[2] * v[2]


def _norm3(v, eps=_TINY):
    sq = _dot(v, v)
    ok = sq > eps
    return jnp.where(ok, jnp.sqrt(jnp.where(ok, sq, 1.0)), 0.0)


class _EdgeFrame(NamedTuple):
    """An edge's quantities under a light direction (components as 3-tuples of arrays).

    a, b the segment's ends; n the outward normal; m the light direction across the edge
    (both over c = |t x L|); along = seg_perp / |seg_perp|^2 (seg_perp: the segment seen
    along the light), so that (x - a) . along is where x lies along the segment.
    """

    a: tuple
    b: tuple
    n: tuple
    m: tuple
    along: tuple
    c: jax.Array
    t_out: jax.Array
    t_in: jax.Array


def _edge_frame(a, b, outward_sign, light, k, rule: str, paper_normal=None) -> _EdgeFrame:
    seg = tuple(bi - ai for ai, bi in zip(a, b))
    length = jnp.maximum(_norm3(seg), 1e-12)
    t = tuple(si / length for si in seg)
    cvec = (t[1] * light[2] - t[2] * light[1], t[2] * light[0] - t[0] * light[2],
            t[0] * light[1] - t[1] * light[0])
    c = jnp.maximum(_norm3(cvec), 1e-12)
    n = tuple(outward_sign * ci / c for ci in cvec)
    lt = _dot(light, t)
    m = tuple((li - lt * ti) / c for li, ti in zip(light, t))
    sl = _dot(seg, light)
    seg_perp = tuple(si - sl * li for si, li in zip(seg, light))
    sp2 = _dot(seg_perp, seg_perp)
    sp2 = jnp.where(sp2 > 1e-24, sp2, 1e-24)
    along = tuple(pi / sp2 for pi in seg_perp)
    if rule == "edge":
        t_out = k / c
        t_in = t_out
    elif rule == "paper":
        if paper_normal is None:
            raise ValueError("the paper rule needs per-edge normals")
        nn = _dot(paper_normal, n)
        nm = _dot(paper_normal, m)
        # N leans outward at a silhouette; guard the rare edge where it does not.
        nn = jnp.maximum(nn, 1e-6)
        t_out = k * nn / jnp.maximum(c + k * nm, 1e-9)
        t_in = k * nn / jnp.maximum(c - k * nm, 1e-9)
    else:
        raise ValueError(f"unknown expansion rule {rule!r}; choose one of {RULES}")
    return _EdgeFrame(a, b, n, m, along, c, t_out, t_in)


def _coordinate(x, f: _EdgeFrame, light, inside, near_boundary):
    """u and du/dT of points x (3-tuple) against edge frames f (see ``penumbra_coordinate``)."""
    w = tuple(xi - ai for xi, ai in zip(x, f.a))
    num = _dot(w, f.n)
    den = _dot(w, f.m)
    scale = _norm3(w) + 1e-12
    # Angular distance (as a tangent, in units of 1/c) from the sun centre to the edge: to the
    # edge's plane where the point lies beside the segment seen along L, else to the end vertex.
    tan_plane = jnp.abs(_safe_div(num, den, 1e-9 * scale))
    along = _dot(w, f.along)
    after = along > 1.0
    beyond = (along < 0.0) | after
    end_vec = tuple(jnp.where(after, xi - bi, wi) for xi, bi, wi in zip(x, f.b, w))
    end_depth = _dot(end_vec, light)
    end_perp = tuple(ei - end_depth * li for ei, li in zip(end_vec, light))
    end_scale = _norm3(end_vec) + 1e-12
    tan_end = _safe_div(_norm3(end_perp), end_depth * f.c, 1e-9 * end_scale)
    depth = jnp.where(beyond, end_depth, den)
    upstream = depth <= 1e-9 * jnp.where(beyond, end_scale, scale)
    magnitude = jnp.where(upstream, 1e6, jnp.minimum(jnp.where(beyond, tan_end, tan_plane), 1e6))
    # The side: beside the segment and within half a half-width of its plane, the plane's own
    # side (so it follows the edge as the sun or pose moves); elsewhere the hard shadow's,
    # so k = 0 gives exactly the hard shadow and concave corners never light the umbra.
    near_plane = (~beyond) & (~upstream) & (tan_plane < 0.5 * 0.5 * (f.t_out + f.t_in))
    if near_boundary is not None:  # only where the plan saw the hard shadow's boundary itself
        near_plane = near_plane & (near_boundary > 0.5)
    side = jnp.where(near_plane, jnp.where(num < 0, -1.0, 1.0), jnp.where(inside > 0.5, -1.0, 1.0))
    u = (2.0 * side * magnitude - f.t_out + f.t_in) / (f.t_out + f.t_in)
    # The same coordinate against the edge's whole line, its side from the edge's own plane
    # (beyond the segment too): what a corner's wedge is made of (``corner_mass``).
    line_mag = jnp.where(upstream, 1e6, jnp.minimum(tan_plane, 1e6))
    u_line = (2.0 * jnp.where(num < 0, -1.0, 1.0) * line_mag - f.t_out + f.t_in) / (f.t_out + f.t_in)
    return jnp.clip(u, -1e6, 1e6), 2.0 / (f.t_out + f.t_in), jnp.clip(u_line, -1e6, 1e6), along


def _range_k(range_k, dtype):
    return jnp.maximum(jnp.asarray(range_k, dtype=dtype), _K_MIN)


def penumbra_coordinate(points: Float[Array, "n 3"], a: Float[Array, "n 3"], b: Float[Array, "n 3"],
                        outward_sign: Float[Array, " n"], light: Float[Array, "*n 3"], range_k,
                        inside: Float[Array, " n"], rule: Rule = "edge",
                        paper_normal: Float[Array, "n 3"] | None = None, with_slope: bool = False,
                        near_boundary: Float[Array, " n"] | None = None):
    """Normalised penumbra coordinate u (n,) of each point against its own edge segment (a, b).

    light: (3,), or (n, 3) one per point. With ``with_slope`` also returns du/dT (n,),
    the factor between u and the angular tangent T it is made from (2 / (T_out + T_in),
    the only place k enters), so a caller can scale a precomputed spatial gradient of T
    instead of differentiating u again.

    u = +1 on the expanded silhouette, -1 on the contracted one, |u| > 1 outside
    the penumbra. Its size comes from the edge's plane where the point, seen
    along the light, lies beside the segment (the documented definition), and
    from the angular distance to the end vertex beyond the ends (so convex
    corners are rounded); its sign comes from the edge's plane near the segment
    (within half a penumbra half-width, where the plan found the shadow's boundary:
    ``near_boundary``) and from ``inside`` (1 in the hard shadow,
    0 outside) elsewhere, so a concave corner never lights up the umbra.
    """
    L = _split(light)
    f = _edge_frame(_split(a), _split(b), outward_sign, L, _range_k(range_k, points.dtype), rule,
                    None if paper_normal is None else _split(paper_normal))
    u, slope, _, _ = _coordinate(_split(points), f, L, inside, near_boundary)
    return (u, slope) if with_slope else u


def _choose(x, edge_ids, edge_vertices_world, outward_sign, light, k, inside, rule, paper, near_boundary):
    """Index (n,) of each point's chosen candidate (smallest |u|), and that candidate's u and du/dT
    (n,) each, without gradients."""
    n_pts, n_cand = edge_ids.shape
    sg = jax.lax.stop_gradient
    flat = edge_ids.reshape(-1)
    rep = lambda v: jnp.repeat(v, n_cand, axis=0)
    L_c = _split(sg(light) if light.ndim == 1 else rep(sg(light)))
    # Each candidate's edge quantities from its gathered vertices: recomputing them costs less
    # than gathering a per-edge table of them (gathers dominate on CPU).
    ev = sg(edge_vertices_world).reshape(-1, 6)[flat]
    f_c = _edge_frame((ev[:, 0], ev[:, 1], ev[:, 2]), (ev[:, 3], ev[:, 4], ev[:, 5]),
                      sg(outward_sign)[flat], L_c, sg(k), rule,
                      None if paper is None else _split(sg(paper)[flat]))
    # Only the nearest boundary edge (the first candidate) may set the side from its plane.
    nb_c = None if near_boundary is None else (
        near_boundary[:, None] * (jnp.arange(n_cand) == 0)[None, :]).reshape(-1)
    u_all, slope_all = _coordinate(tuple(rep(sg(xi)) for xi in x), f_c, L_c, rep(sg(inside)), nb_c)[:2]
    # Ties (edges meeting at a vertex give the same u beyond it, with different slopes and
    # gradients) go to the earlier candidate, so rounding cannot flip the choice: a fit's loss
    # jumped under 1e-12 steps and its LM solver stalled on rejected steps.
    abs_u = jnp.abs(u_all.reshape(n_pts, n_cand))
    # A slot repeating an earlier one (plans fill missing slots with the first edge) is never
    # chosen: without the first slot's boundary flag its side can differ (the paper rule's ramp
    # is not symmetric), and the choice would depend on how many distinct edges were found.
    repeated = [jnp.zeros(n_pts, bool)] + [jnp.any(edge_ids[:, :j] == edge_ids[:, j:j + 1], axis=1)
                                           for j in range(1, n_cand)]
    abs_u = jnp.where(jnp.stack(repeated, axis=1), jnp.inf, abs_u)
    tie = 8 * jnp.finfo(abs_u.dtype).eps  # a few ulps, in float32 and float64 alike
    best = jnp.argmin(abs_u + tie * (1.0 + abs_u) * jnp.arange(n_cand), axis=1)
    pick = lambda v: sg(jnp.take_along_axis(v.reshape(n_pts, n_cand), best[:, None], axis=1)[:, 0])
    return best, (pick(u_all), pick(slope_all))


@functools.partial(jax.custom_jvp, nondiff_argnums=(0,))
def _chosen_coordinate(rule, chosen, x, edge, light, k, inside, near_boundary):
    """u and du/dT (n,) of points x (3-tuple) against their chosen edges: ``chosen``, the values
    ``_choose`` computed for them (the same arithmetic), so that a forward pass evaluates each
    point's edges once; edge: (a, b, outward_sign, paper normal or None), each edge's, per point.
    The derivatives are this edge's alone (``_chosen_jvp``): autodiff costs one edge per point."""
    return chosen


def _chosen_from_edge(rule, x, edge, light, k, inside, near_boundary):
    a, b, sign, paper = edge
    return _coordinate(x, _edge_frame(a, b, sign, light, k, rule, paper), light, inside, near_boundary)[:2]


def _chosen_jvp(rule, primals, tangents):
    chosen, *args = primals
    _, *d_args = tangents  # the choice's own tangent is zero (made without gradients)
    # Only the inputs that carry a tangent are differentiated (the others, symbolic zeros, are
    # constants here: a pixel's slope needs the points' alone, not the edges' and the light's).
    leaves, tree = jax.tree_util.tree_flatten(tuple(args))
    d_leaves = jax.tree_util.tree_leaves(tuple(d_args), is_leaf=lambda t: isinstance(t, _SymbolicZero))
    live = [not isinstance(t, _SymbolicZero) for t in d_leaves]

    def of_live(*values):
        it = iter(values)
        full = [next(it) if on else leaf for leaf, on in zip(leaves, live)]
        return _chosen_from_edge(rule, *jax.tree_util.tree_unflatten(tree, full))

    if any(live):
        _, d_out = jax.jvp(of_live, tuple(x for x, on in zip(leaves, live) if on),
                           tuple(t for t, on in zip(d_leaves, live) if on))
    else:
        d_out = jax.tree_util.tree_map(jnp.zeros_like, chosen)
    # The value through this function again, so that a derivative of a derivative (u's slope
    # across a pixel, differentiated by a fit) takes this rule too.
    return _chosen_coordinate(rule, chosen, *args), d_out


_SymbolicZero = jax.custom_derivatives.SymbolicZero
_chosen_coordinate.defjvp(_chosen_jvp, symbolic_zeros=True)


def _pixel_directions(pixel_axes, x, dtype):
    """The two pixel axes as per-point component tuples (tangents for ``jax.linearize``)."""
    axes = jnp.asarray(pixel_axes, dtype)
    return [tuple(jnp.broadcast_to(c, x[0].shape) for c in _split(axes[..., i, :])) for i in (0, 1)]


def edge_coordinate(points, edge_ids: Int[Array, "n K"], edge_vertices_world: Float[Array, "s 2 3"],
                    outward_sign: Float[Array, " s"], light, range_k, inside: Float[Array, " n"],
                    rule: Rule = "edge", paper_normal_world: Float[Array, "s 3"] | None = None,
                    with_slope: bool = False, near_boundary: Float[Array, " n"] | None = None,
                    pixel_axes: Float[Array, "*n 2 3"] | None = None):
    """Penumbra coordinate u (n,) at points (n, 3) against their candidate edges (n, K).

    light: (3,), or (n, 3) one per point. Each point takes the candidate nearest in
    penumbra units (smallest |u|): the silhouette that the sun disk sees first. The
    choice is piecewise constant, so it is made without gradients over all candidates; its u
    is the value, and u's derivatives are the chosen edge's alone (``_chosen_coordinate``):
    gradients cost one edge per point, and a forward pass evaluates each candidate once.

    pixel_axes: (2, 3) or (n, 2, 3), the receiver's offsets (m) across a whole pixel along
    its two sides; with them, also returns u's change across the pixel along each side,
    du_a and du_b (n,) (forward-mode derivatives of u along the axes, themselves
    differentiable), for ``footprint_profile_alpha``: (u, du_a, du_b), or
    (u, slope, du_a, du_b) with ``with_slope``.
    """
    k = _range_k(range_k, points.dtype)
    x = _split(points)
    paper = paper_normal_world
    best, chosen = _choose(x, edge_ids, edge_vertices_world, outward_sign, light, k, inside, rule, paper,
                           near_boundary)
    # -- the gradient: the chosen edge only (its value is the choice's) --
    eid = jnp.take_along_axis(edge_ids, best[:, None], axis=1)[:, 0]
    ev = edge_vertices_world[eid]
    edge = (_split(ev[:, 0]), _split(ev[:, 1]), outward_sign[eid], None if paper is None else _split(paper[eid]))
    L = _split(light)
    nb = None if near_boundary is None else jnp.where(best == 0, near_boundary, 0.0)
    if pixel_axes is None:
        u, slope = _chosen_coordinate(rule, chosen, x, edge, L, k, inside, nb)
        return (u, slope) if with_slope else u
    u_of = lambda xx: _chosen_coordinate(rule, chosen, xx, edge, L, k, inside, nb)
    # One primal pass, its linearisation applied to both axes.
    (u, slope), lin = jax.linearize(u_of, x)
    dir_a, dir_b = _pixel_directions(pixel_axes, x, points.dtype)
    du_a, du_b = lin(dir_a)[0], lin(dir_b)[0]
    return (u, slope, du_a, du_b) if with_slope else (u, du_a, du_b)


def edge_alpha(points, edge_ids: Int[Array, "n K"], edge_vertices_world: Float[Array, "s 2 3"],
               outward_sign: Float[Array, " s"], light, range_k, inside: Float[Array, " n"],
               rule: Rule = "edge", profile: Profile = "linear",
               paper_normal_world: Float[Array, "s 3"] | None = None,
               near_boundary: Float[Array, " n"] | None = None,
               pixel_axes: Float[Array, "*n 2 3"] | None = None,
               neighbours: Int[Array, "s 2"] | None = None):
    """Alpha (n,) at points (n, 3) against their candidate edges (n, K); see ``edge_coordinate``.

    With ``pixel_axes`` (see there) alpha is averaged over each pixel's footprint
    (``footprint_profile_alpha``), else sampled at the points. With ``neighbours`` (s, 2),
    each edge's outline neighbour sharing its first and its second vertex (-1: none), a
    point near a corner of the outline gets the occluded mass of the corner's wedge
    (``corner_alpha``) instead of its nearest edge's half-plane.
    """
    if neighbours is not None:
        return corner_alpha(points, edge_ids, edge_vertices_world, outward_sign, light, range_k, inside,
                            neighbours, rule, profile, paper_normal_world, near_boundary, pixel_axes)
    out = edge_coordinate(points, edge_ids, edge_vertices_world, outward_sign, light, range_k, inside,
                          rule, paper_normal_world, near_boundary=near_boundary, pixel_axes=pixel_axes)
    if pixel_axes is None:
        return profile_alpha(out, profile)
    u, du_a, du_b = out
    return footprint_profile_alpha(u, du_a, du_b, profile)


def profile_slope(u, profile: Profile = "linear"):
    """d alpha / d u of ``profile_alpha`` (0 outside the ramp)."""
    if profile == "linear":
        return jnp.where(jnp.abs(u) < 1.0, -0.5, 0.0)
    if profile == "disk":
        uc = jnp.clip(u, -1.0, 1.0)
        return -2.0 * jnp.sqrt(jnp.maximum(1.0 - uc * uc, 0.0)) / jnp.pi
    raise ValueError(f"unknown penumbra profile {profile!r}; choose one of {PROFILES}")


@functools.partial(jax.custom_jvp, nondiff_argnums=(1,))
def profile_integral(u, profile: Profile = "linear"):
    """The antiderivative of ``profile_alpha`` in u: 0 for u >= 1, u for u <= -1 (where alpha is 1).

    linear: -(1 - u)^2 / 4 on [-1, 1]; disk: (u acos u - sqrt(1 - u^2) + (1 - u^2)^(3/2) / 3) / pi.
    Its JVP is ``profile_alpha`` itself (the disk's terms have infinite slopes at u = +-1 that
    cancel; the custom JVP keeps them out).
    """
    u = jnp.asarray(u)
    uc = jnp.clip(u, -1.0, 1.0)
    if profile == "linear":
        inner = -0.25 * (1.0 - uc) ** 2
    elif profile == "disk":
        s = jnp.maximum(1.0 - uc * uc, 0.0)
        root = jnp.sqrt(s)
        inner = (uc * jnp.arccos(uc) - root + s * root / 3.0) / jnp.pi
    else:
        raise ValueError(f"unknown penumbra profile {profile!r}; choose one of {PROFILES}")
    return jnp.where(u < -1.0, u, inner)


@profile_integral.defjvp
def _profile_integral_jvp(profile, primals, tangents):
    (u,), (du,) = primals, tangents
    return profile_integral(u, profile), profile_alpha(u, profile) * du


_BOX_MIN = 1e-3      # half-widths (u units) below this: the box is its centre value (error < 1e-4)
_FOOTPRINT_NODES = 3  # Gauss-Legendre nodes across the pixel's narrower direction


def _box_profile_alpha(v, half, profile: Profile):
    """Mean of ``profile_alpha`` over [v - half, v + half], exactly (difference of its integral)."""
    ok = half > _BOX_MIN
    h = jnp.where(ok, half, 1.0)
    mean = (profile_integral(v + h, profile) - profile_integral(v - h, profile)) / (2.0 * h)
    return jnp.where(ok, mean, profile_alpha(v, profile))


def footprint_profile_alpha(u, du_a, du_b, profile: Profile = "linear"):
    """Alpha averaged over a pixel's footprint, in penumbra units; u, du_a, du_b broadcast.

    u: the penumbra coordinate at the pixel's centre; du_a, du_b: its change across the
    whole pixel along the pixel's two sides (u is taken as linear over the pixel, so the
    footprint's u is the centre's plus a sum of two uniform variables of half-widths
    |du_a| / 2 and |du_b| / 2: a trapezoid). Exact along the wider side (the difference of
    ``profile_integral``), Gauss-Legendre with 3 nodes along the narrower one (within 6e-4 of a brute-force mean), where the
    integrand is already smoothed by the wider box. With du_a = du_b = 0 it is
    ``profile_alpha``. The box of one pixel has variance 1/12 px^2: the Gaussian that
    ``pixel_profile.blurred_profile_alpha`` (the fitter's model of a photographed pixel, which
    adds the camera's blur) takes for the same footprint has the same variance.
    """
    nodes, half, w = _footprint_nodes(u, du_a, du_b)
    return _box_profile_alpha(nodes, half, profile) @ w


def _footprint_nodes(u, du_a, du_b):
    """The footprint's Gauss-Legendre nodes in u across the narrower side (..., n), the box's
    half-width along the wider side (..., 1) and the nodes' weights (n,) (``footprint_profile_alpha``)."""
    u, du_a, du_b = jnp.asarray(u), jnp.abs(jnp.asarray(du_a)), jnp.abs(jnp.asarray(du_b))
    wide = 0.5 * jnp.maximum(du_a, du_b)
    narrow = 0.5 * jnp.minimum(du_a, du_b)
    # Far outside the ramp the mean is exactly 0 or 1: clip u there, so that the out-of-band
    # sentinels (+-1e6) do not cancel catastrophically in the integral's difference.
    reach = 2.0 + wide + narrow
    v = jnp.clip(u, -reach, reach)
    z, w = np.polynomial.legendre.leggauss(_FOOTPRINT_NODES)
    dtype = jnp.result_type(v)
    z, w = jnp.asarray(z, dtype), jnp.asarray(0.5 * w, dtype)
    return v[..., None] + narrow[..., None] * z, wide[..., None], w


def _box_step(v, half):
    """Mean of the hard step [u < 0] over [v - half, v + half]."""
    ok = half > _BOX_MIN
    h = jnp.where(ok, half, 1.0)
    return jnp.where(ok, jnp.clip((h - v) / (2.0 * h), 0.0, 1.0), (v < 0).astype(jnp.result_type(v)))


def footprint_bump(u, du_a, du_b, profile: Profile = "linear"):
    """The footprint mean (as ``footprint_profile_alpha``) of profile_alpha(u) - [u < 0]: the
    penumbra's departure from the hard shadow of one straight edge, over a pixel. It is 0 where
    the pixel does not reach the ramp, and tends to 0 as the ramp narrows within the pixel (the
    ramp's departure is odd about its middle), so a footprint mean of alpha is the hard
    shadow's area in the pixel plus this (``wedge.wedge_alpha``)."""
    nodes, half, w = _footprint_nodes(u, du_a, du_b)
    return (_box_profile_alpha(nodes, half, profile) - _box_step(nodes, half)) @ w


def _fan_parts(y, d, h):
    """Shared pieces of ``_fan``: whether the apex direction lies within the disk's chord, the
    clipped angle psi_c, r2 = y^2 + (h d)^2 (guarded) and d^2 - r2 (>= 0)."""
    r2 = y * y + (h * d) ** 2
    ok = h < 1.0
    # |psi| < acos h  <=>  d^2 (1 - h^2) > y^2 (for h > 0, and its limit at h = 0).
    within = ok & (d * d * (1.0 - h * h) > y * y)
    safe = r2 > 1e-300
    psi = jnp.arctan2(jnp.where(safe, y, 0.0), jnp.where(safe, h * d, 1.0))
    hs = jnp.where(ok, h, 1.0)
    psi_c = jnp.where(within, psi, jnp.sign(y) * jnp.arccos(hs))
    return ok, within, psi_c, jnp.where(safe, r2, 1.0), jnp.maximum(d * d - r2, 0.0), hs


@functools.partial(jax.custom_jvp, nondiff_argnums=(3,))
def _fan(y, d, h, profile: Profile):
    """Gamma(psi, h) = int_0^psi g(h / cos p) dp over the part where h / cos p < 1 (0 for h >= 1).

    The light's deficit along a straight line at distance h >= 0 from the sun's centre (in sun
    radii), swept from the foot of the perpendicular to the direction psi = atan2(y, h d) of a
    point on it (y: its position along the line from the foot, times d > 0): g(R) = 1 - R^2
    for the uniform disk (``disk``), sqrt(1 - R^2) for the light of density
    1 / (2 pi sqrt(1 - r^2)) whose edge profile is the linear ramp (``linear``). Closed forms
    (psi clipped to +-acos h): disk psi - h^2 tan psi; linear asin(sin psi / sqrt(1 - h^2))
    - h atan(h sin psi / sqrt(cos^2 psi - h^2)). Written in (y, d, h), not psi, so that values
    and derivatives have their limits at h = 0 (a point on the line). Gamma(pi / 2, h) / pi is
    the half-plane's profile. The custom JVP keeps the closed forms' cancelling infinite
    slopes at psi = +-acos h out.
    """
    ok, within, psi_c, r2, rest, hs = _fan_parts(y, d, h)
    sy = jnp.sign(y)
    if profile == "disk":
        # h^2 tan psi: h y / d within, h sqrt(1 - h^2) (with y's sign) where clipped.
        val = psi_c - jnp.where(within, hs * y / jnp.where(within, d, 1.0),
                                sy * hs * jnp.sqrt(jnp.maximum(1.0 - hs * hs, 0.0)))
    elif profile == "linear":
        root = jnp.sqrt(rest)
        val = jnp.where(within, jnp.arctan2(y, hs * root) - hs * jnp.arctan2(y, root),
                        sy * 0.5 * np.pi * (1.0 - hs))
    else:
        raise ValueError(f"unknown penumbra profile {profile!r}; choose one of {PROFILES}")
    return jnp.where(ok, val, 0.0)


@_fan.defjvp
def _fan_jvp(profile, primals, tangents):
    (y, d, h), (dy, dd, dh) = primals, tangents
    ok, within, psi_c, r2, rest, hs = _fan_parts(y, d, h)
    sy = jnp.sign(y)
    d_safe = jnp.where(within, d, 1.0)
    rr = jnp.where(within, r2 / (d_safe * d_safe), 1.0)  # R^2 at the apex direction
    g = 1.0 - rr if profile == "disk" else jnp.sqrt(jnp.maximum(1.0 - rr, 0.0))
    dpsi = (h * d * dy - y * (d * dh + h * dd)) / r2
    if profile == "disk":
        g_h = jnp.where(within, -2.0 * y / d_safe, -2.0 * sy * jnp.sqrt(jnp.maximum(1.0 - hs * hs, 0.0)))
    else:
        g_h = -jnp.arctan2(y, jnp.sqrt(rest))
    tangent = jnp.where(within, g * dpsi, 0.0) + g_h * dh
    return _fan(y, d, h, profile), jnp.where(ok, tangent, 0.0)


_VERTEX_U = 1e-6  # both lines nearer the sun's centre than this (sun radii): the vertex's own value


def corner_mass(u1, u2, cos_n, sin_n, convex, profile: Profile = "linear"):
    """Occluded fraction of the light behind a corner of two straight edges; all args broadcast.

    u1, u2: the sun centre's signed distances (in penumbra units, +1 outer, -1 inner
    silhouette: ``profile_alpha``'s u) to the two edges' lines, positive on the lit side;
    cos_n, sin_n >= 0: cosine and |sine| of the angle between the lines' outward normals;
    convex: the occluder is the intersection of the two half-planes (else their union).
    In the sun's view (gnomonic, in sun radii) the sun is the unit disk D and each edge a
    line; by Green's theorem the light's mass over a polygon P within D is
    mass(P & D) = w + sum over edges of -(1 / 2 pi) int g(R(theta)) d theta over the edge's
    signed angular span where R < 1 (w the winding number, R(theta) the distance to the edge
    along theta, g as ``_fan``). For the wedge, with V its apex, the incoming ray on line 1
    ends at V and the outgoing one on line 2 starts there; the result is symmetric in the
    two lines. A single line (u2 far inside) gives ``profile_alpha(u1)``, two collinear
    lines the same; a 90-degree corner at its apex 1/4.
    """
    sgn = lambda v: jnp.where(v < 0, -1.0, 1.0)
    # A concave corner is 1 - the convex wedge of the lit complement (both normals flipped).
    flip = jnp.where(convex, 1.0, -1.0)
    v1, v2 = flip * u1, flip * u2
    s1, s2 = sgn(v1), sgn(v2)
    h1, h2 = s1 * v1, s2 * v2  # |v|, with the derivative of the side taken at v = 0
    vertex = (h1 < _VERTEX_U) & (h2 < _VERTEX_U)
    # The apex V solves V . n1 = -v1, V . n2 = -v2; its position along each line from the foot
    # of the perpendicular, times sin_n >= 0, is y1 and y2.
    y1 = v1 * cos_n - v2
    y2 = v1 - v2 * cos_n
    w = ((v1 < 0) & (v2 < 0)).astype(h1.dtype)
    # Gamma(pi / 2, h) = pi profile_alpha(h) (h >= 0): the half-plane's own profile.
    mass = w + (s1 * (_fan(y1, sin_n, h1, profile) + np.pi * profile_alpha(h1, profile))
                + s2 * (np.pi * profile_alpha(h2, profile) - _fan(y2, sin_n, h2, profile))) / (2.0 * np.pi)
    # At the apex itself: the wedge's angle over 2 pi, for any radially symmetric light.
    unit = sin_n * sin_n + cos_n * cos_n > 0.25  # a zero-length edge has no normal
    angle = jnp.arctan2(jnp.where(unit, sin_n, 0.0), jnp.where(unit, cos_n, 1.0))
    mass = jnp.where(vertex, (np.pi - angle) / (2.0 * np.pi), mass)
    return jnp.clip(jnp.where(convex, mass, 1.0 - mass), 0.0, 1.0)


_CORNER_NODES = 1  # Gauss-Legendre nodes per pixel axis for a corner's footprint correction (1: the centre)
_APEX_REACH = 4.0  # sun radii from the corner's apex within which the wedge replaces the edge


def corner_alpha(points, edge_ids: Int[Array, "n K"], edge_vertices_world: Float[Array, "s 2 3"],
                 outward_sign: Float[Array, " s"], light, range_k, inside: Float[Array, " n"],
                 neighbours: Int[Array, "s 2"], rule: Rule = "edge", profile: Profile = "linear",
                 paper_normal_world: Float[Array, "s 3"] | None = None,
                 near_boundary: Float[Array, " n"] | None = None,
                 pixel_axes: Float[Array, "*n 2 3"] | None = None):
    """Alpha (n,) at points (n, 3) with corners of the outline: see ``edge_alpha``.

    Each point's chosen edge (as ``edge_coordinate``) and its outline neighbour at the chosen
    edge's end nearer the point (``neighbours``) form a corner, convex where the neighbour's
    far end lies on the occluder's side of the chosen edge's line; alpha is the light's mass
    behind that wedge (``corner_mass``) from the two lines' coordinates. A point keeps the
    single-edge alpha where there is no neighbour, or where the wedge's own inside/outside
    at the point contradicts the plan's hard shadow away from the boundary (the wedge is
    then not the local outline). Far from the corner the wedge is the chosen edge's
    half-plane, so straight or finely tessellated outlines are unchanged.
    With ``pixel_axes``, the single-edge alpha is averaged exactly over the footprint
    (``footprint_profile_alpha``) and the wedge's difference from it with a 2 x 2
    Gauss-Legendre rule over the pixel (the coordinates taken as linear over it).
    """
    k = _range_k(range_k, points.dtype)
    x = _split(points)
    sg = jax.lax.stop_gradient
    paper = paper_normal_world
    best = _choose(x, edge_ids, edge_vertices_world, outward_sign, light, k, inside, rule, paper,
                   near_boundary)[0]
    eid = jnp.take_along_axis(edge_ids, best[:, None], axis=1)[:, 0]
    L = _split(light)
    frame = lambda e: _edge_frame(_split(edge_vertices_world[e][:, 0]), _split(edge_vertices_world[e][:, 1]),
                                  outward_sign[e], L, k, rule, None if paper is None else _split(paper[e]))
    f1 = frame(eid)
    nb = None if near_boundary is None else jnp.where(best == 0, near_boundary, 0.0)
    # The corner: the chosen edge's end nearer the point (seen along the light) and the outline
    # neighbour sharing it (discrete choices, no gradient).
    at_b = sg(_dot(tuple(xi - ai for xi, ai in zip(x, f1.a)), f1.along)) > 0.5
    other = jnp.take_along_axis(neighbours[eid], at_b[:, None].astype(eid.dtype), axis=1)[:, 0]
    has = other >= 0
    f2 = frame(jnp.maximum(other, 0))
    vtx = tuple(jnp.where(at_b, bi, ai) for ai, bi in zip(f1.a, f1.b))
    dist2 = lambda p: sum((pi - vi) ** 2 for pi, vi in zip(p, vtx))
    far = tuple(jnp.where(dist2(f2.a) < dist2(f2.b), bi, ai) for ai, bi in zip(f2.a, f2.b))
    convex = sg(_dot(tuple(fi - vi for fi, vi in zip(far, vtx)), f1.n)) < 0
    cos_n = _dot(f1.n, f2.n)
    n_x = (f1.n[1] * f2.n[2] - f1.n[2] * f2.n[1], f1.n[2] * f2.n[0] - f1.n[0] * f2.n[2],
           f1.n[0] * f2.n[1] - f1.n[1] * f2.n[0])
    sin_n = _norm3(n_x)
    has = has & (cos_n * cos_n + sin_n * sin_n > 0.25)  # both normals are unit vectors: no zero-length edge

    def coords(xx):
        u, _, u1, _ = _coordinate(xx, f1, L, inside, nb)
        return u, u1, _coordinate(xx, f2, L, inside, None)[2]

    mass = lambda a, b: corner_mass(a, b, cos_n, sin_n, convex, profile)
    u, u1, u2 = coords(x)
    # The wedge stands for the outline where it agrees with the plan's hard shadow, or where
    # the plan trusts the edge's plane for the side (near the boundary).
    inside_wedge = jnp.where(convex, (u1 < 0) & (u2 < 0), (u1 < 0) | (u2 < 0))
    # (Within the penumbra of both lines the plan's side is a guess: the wedge decides there.)
    trusted = (inside_wedge == (inside > 0.5)) | ((jnp.abs(u1) < 1.0) & (jnp.abs(u2) < 1.0))
    if nb is not None:
        trusted = trusted | (nb > 0.5)
    # Only near the apex: farther than _APEX_REACH sun radii from it, the light sees one of the
    # lines at most (or a sliver far out), and each edge's line, extended far beyond its segment
    # or seen from upstream of it, bounds nothing there. |V|^2 sin^2 = u1^2 + u2^2 - 2 u1 u2 cos.
    apex2 = u1 * u1 + u2 * u2 - 2.0 * u1 * u2 * cos_n
    near_apex = apex2 < (_APEX_REACH * _APEX_REACH) * sin_n * sin_n
    use = sg(has & trusted & near_apex)
    if pixel_axes is None:
        return jnp.where(use, mass(u1, u2), profile_alpha(u, profile))
    # The single-edge alpha averaged exactly over the footprint (as ``edge_alpha``), plus the
    # Gauss mean of the wedge's difference from it, with the coordinates computed at the nodes
    # themselves (near a vertex on the ground they are far from linear over a pixel). Far from
    # the corner both agree at every node, so the correction vanishes there.
    _, lin = jax.linearize(lambda xx: _coordinate(xx, f1, L, inside, nb)[0], x)
    dir_a, dir_b = _pixel_directions(pixel_axes, x, points.dtype)
    base = footprint_profile_alpha(u, lin(dir_a), lin(dir_b), profile)
    if _CORNER_NODES == 1:  # the pixel's centre: the coordinates are already there
        return jnp.clip(base + jnp.where(use, mass(u1, u2) - profile_alpha(u, profile), 0.0), 0.0, 1.0)
    z, wts = np.polynomial.legendre.leggauss(_CORNER_NODES)
    corr = 0.0
    for za, wa in zip(z, wts):
        for zb, wb in zip(z, wts):
            un, u1n, u2n = coords(tuple(xi + 0.5 * (za * ai + zb * bi) for xi, ai, bi in zip(x, dir_a, dir_b)))
            corr = corr + (0.25 * wa * wb) * (mass(u1n, u2n) - profile_alpha(un, profile))
    return jnp.clip(base + jnp.where(use, corr, 0.0), 0.0, 1.0)


def shade(alpha, rho, sky_hidden=None):
    """Shadow factor 1 - alpha (1 - rho) - rho h: irradiance over open ground's lit irradiance,
    in linear units; h (``sky_hidden``, default 0) the fraction of the cosine-weighted sky that
    the object hides from the receiver (``softshadow.sky``)."""
    out = 1.0 - alpha * (1.0 - rho)
    return out if sky_hidden is None else out - rho * sky_hidden
