"""The ``wedge`` rule: the fraction of the sun's disk that the mesh hides, from its silhouette
edges (JAX, differentiable).

Seen from a receiver point x, the sun is a disk of angular radius r around s = -L. In the
gnomonic plane perpendicular to s (units: tan r, so the sun is the unit disk D centred on the
origin), every silhouette edge in front of x is a straight segment, and the mesh covers each
point p of the plane W(p) times: the number of lit layers the ray from x through p crosses
(the depth complexity). W changes by the edge's jump w (1 for a closed mesh) across each
segment, growing towards the side of the edge's lit face. The sun is hidden where W >= 1, so

    alpha(x) = mass of the light over {W >= 1} within D

(penumbra wedges / soft shadow volumes, with the union taken exactly: overlapping outline loops
of the mesh seen from the sun count once, thin gaps let through the light they let through).
By Green's theorem in polar coordinates about the disk's centre,

    alpha = [W(0) >= 1] - (1 / 2 pi) sum over the pieces of segments on the boundary of {W >= 1}
            of sigma (Gamma(psi_1, h) - Gamma(psi_0, h)),

with h the centre's distance to the segment's line, psi the angle along the line seen from the
centre (from the foot of the perpendicular), sigma the side of the line the centre lies on, and
Gamma = ``penumbra._fan``, the light's deficit over the angle (closed forms for the uniform disk
``disk`` and for the light whose straight-edge profile is the linear ramp, ``linear``). A piece
of segment j is on the boundary where W just beside it, on its lit side, is 0; W there is W(0)
plus the signed crossings of the path from the centre, and along the segment it changes only
where another segment crosses it. So per point, with K candidate segments: K^2 intersections,
K^2 path tests and K (K + 1) fans. A single straight edge gives exactly ``profile_alpha(u)``:
the ``edge`` rule's profile, with the same k (k = tan r for ``disk``).

The discrete parts (which pieces lie on the boundary, W(0)) are made without gradients; the
geometry (the segments' ends, the intersections along them, the lines' distances) carries them,
so alpha is differentiable in k, the sun and the pose, and continuous where the arrangement's
combinatorics change (the area does not jump there).

The plan (``softshadow.wedge_plan``) makes the discrete choices once, in NumPy: the candidate
edges, the depth complexity W(0) at the sun's centre, and along each segment where it lies on
the boundary (its statuses at its ends and the crossings where they change). It hands a flat
list of (point, edge) pairs of the segments that bound {W >= 1} or cross such a segment, and of
their crossings; here each pair's segment is projected, its fans summed onto its point. The
hard term [W(0) >= 1] comes as an offset F = [W(0) >= 1] - S / 2 pi, S the angle the boundary's
pieces subtend at the centre at the plan's parameters: [W(0) >= 1] = round(F + S / 2 pi) follows
the centre across a piece of the boundary when the sun or the pose move it over the centre (S
jumps by a whole turn there), as long as the boundary's far parts turn by much less than half a
turn (a move of much less than a penumbra).
"""

from __future__ import annotations

import dataclasses
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from .penumbra import _fan, footprint_bump, profile_alpha

__all__ = ["gnomonic_segments", "pixel_hard_area", "pixel_mean_alpha", "pixel_segments", "wedge_alpha"]

_DEPTH_MIN = 1e-7       # metres in front of the receiver at which segments are clipped
_DEPTH_REL = 1e-6       # ... plus this fraction of the vertex's offset (L1 norm)
_K_MIN = 1e-9           # the disk's radius (tan r) is at least this: keeps 1/k finite
_SIDE_TOL = 1e-10       # |u| (sun radii, pixels) below this: the origin counts as on the line's lit side
_SIDE_TOL_32 = 1e-5     # ... in float32


def _cross(ax, ay, bx, by):
    return ax * by - ay * bx


def _cross3(u, v):
    return (u[1] * v[2] - u[2] * v[1], u[2] * v[0] - u[0] * v[2], u[0] * v[1] - u[1] * v[0])


def _dot3(u, v):
    return u[0] * v[0] + u[1] * v[1] + u[2] * v[2]


def gnomonic_segments(points, a, b, flip, light, scale=1.0):
    """The segments (a, b) seen from points, in the gnomonic plane of the sun's centre.

    points, a, b (P, 3): each pair's receiver point and the edge's ends; flip (P,): the plan's
    choice of direction (1: from b to a), so that the edge's covered side is on the left; light
    (3,) or (P, 3). Returns (ax, ay, bx, by) (P,) each: the segment's ends in units of ``scale``
    (tan of the angle from the sun's centre). The part behind the point is clipped off at a depth
    of ``_DEPTH_MIN``. The arithmetic of ``wedge_plan.arrangement``.
    """
    s, e1, e2 = _light_frame(jnp.asarray(light))
    x = tuple(points[..., i] for i in range(3))
    wa = tuple(a[..., i] - x[i] for i in range(3))
    wb = tuple(b[..., i] - x[i] for i in range(3))
    da, db = _dot3(wa, s), _dot3(wb, s)
    l1 = lambda v: jnp.abs(v[0]) + jnp.abs(v[1]) + jnp.abs(v[2])
    dmin = _DEPTH_MIN + _DEPTH_REL * jnp.maximum(l1(wa), l1(wb))
    keep = (da > dmin) | (db > dmin)
    step = db - da
    t = jnp.clip((dmin - da) / jnp.where(step != 0, step, 1.0), 0.0, 1.0)
    ta = jnp.where((da < dmin) & keep, t, 0.0)
    tb = jnp.where((db < dmin) & keep, t, 1.0)
    pa = tuple(wa[i] + ta * (wb[i] - wa[i]) for i in range(3))
    pb = tuple(wa[i] + tb * (wb[i] - wa[i]) for i in range(3))
    dpa = jnp.where(keep, da + ta * step, 1.0)
    dpb = jnp.where(keep, da + tb * step, 1.0)
    px, py = _dot3(pa, e1) / dpa, _dot3(pa, e2) / dpa
    qx, qy = _dot3(pb, e1) / dpb, _dot3(pb, e2) / dpb
    swap = flip > 0.5
    inv = 1.0 / scale
    ax, ay = jnp.where(swap, qx, px) * inv, jnp.where(swap, qy, py) * inv
    bx, by = jnp.where(swap, px, qx) * inv, jnp.where(swap, py, qy) * inv
    return ax, ay, bx, by


def _light_frame(light):
    """Unit s = -L and an orthonormal (e1, e2) spanning the plane perpendicular to it (e1 x e2 =
    s), as component tuples; light (3,) or (P, 3). The helper axis (the world axis least aligned
    with the light) is a discrete choice: nothing depends on the frame's rotation about s."""
    sg = jax.lax.stop_gradient
    s = tuple(-light[..., i] for i in range(3))
    mag = jnp.stack([jnp.abs(sg(c)) for c in s], -1)
    pick = jnp.argmin(mag, axis=-1)
    axis = tuple((pick == i).astype(light.dtype) for i in range(3))
    e1 = _cross3(axis, s)
    norm = jnp.sqrt(_dot3(e1, e1))
    e1 = tuple(c / norm for c in e1)
    return s, e1, _cross3(s, e1)


def pixel_segments(points, a, b, flip, light, pixel_axes):
    """The segments' shadows on each pixel's plane, in pixel units (the pixel is the unit square
    about the point): v - x = al A + be B + t s along the sun's direction s, A and B the pixel's
    sides (pixel_axes (P, 2, 3)); points, a, b (P, 3); flip (P,) the plan's choice of direction
    (covered side on the left; mirrored axes are swapped). Returns (ax, ay, bx, by) (P,): the whole
    segment projected along s, on either side of the plane (as the ground's hard shadow projects
    the whole mesh; a hard cut at t = 0 would jump by a finite part of an edge lying in the plane,
    the base of an object standing on it, when it tilts by a hair). The arithmetic of
    ``wedge_plan.arrangement``."""
    sg = jax.lax.stop_gradient
    light = jnp.asarray(light)
    s = tuple(-light[..., i] for i in range(3))
    A = tuple(pixel_axes[..., 0, i] for i in range(3))
    B = tuple(pixel_axes[..., 1, i] for i in range(3))
    c_bs, c_sa = _cross3(B, s), _cross3(s, A)
    det = _dot3(A, c_bs)
    det = jnp.where(det == 0, 1.0, det)
    mirror = sg(det) < 0
    x = tuple(points[..., i] for i in range(3))
    wa = tuple(a[..., i] - x[i] for i in range(3))
    wb = tuple(b[..., i] - x[i] for i in range(3))
    px, py = _dot3(c_bs, wa) / det, _dot3(c_sa, wa) / det
    qx, qy = _dot3(c_bs, wb) / det, _dot3(c_sa, wb) / det
    px, py = jnp.where(mirror, py, px), jnp.where(mirror, px, py)
    qx, qy = jnp.where(mirror, qy, qx), jnp.where(mirror, qx, qy)
    swap = flip > 0.5
    ax, ay = jnp.where(swap, qx, px), jnp.where(swap, qy, py)
    bx, by = jnp.where(swap, px, qx), jnp.where(swap, py, qy)
    return ax, ay, bx, by


class _Lines(NamedTuple):
    """Each pair's segment as a line seen from the origin: unit direction (tx, ty), the origin's
    signed distance u (+ on the lit side), the ends' positions ya, yb from the foot of the
    perpendicular, and the segment's length."""

    tx: jax.Array
    ty: jax.Array
    u: jax.Array
    ya: jax.Array
    yb: jax.Array
    length: jax.Array


def _lines(ax, ay, bx, by) -> _Lines:
    dx, dy = bx - ax, by - ay
    len2 = dx * dx + dy * dy
    ok = len2 > 0
    length = jnp.where(ok, jnp.sqrt(jnp.where(ok, len2, 1.0)), 0.0)
    ln = jnp.where(ok, length, 1.0)
    tx, ty = jnp.where(ok, dx / ln, 1.0), jnp.where(ok, dy / ln, 0.0)
    ya = ax * tx + ay * ty
    return _Lines(tx, ty, ay * tx - ax * ty, ya, ya + length, length)


def _crossing_along(ax, ay, bx, by, lines: _Lines, cross):
    """Where along segment j each crossing (C, 2) pairs (j, i) lies (its y), clamped to j."""
    j, i = cross[:, 0], cross[:, 1]
    dxj, dyj = bx[j] - ax[j], by[j] - ay[j]
    dxi, dyi = bx[i] - ax[i], by[i] - ay[i]
    den = _cross(dxj, dyj, dxi, dyi)
    ok = den != 0
    t = jnp.clip(_cross(ax[i] - ax[j], ay[i] - ay[j], dxi, dyi) / jnp.where(ok, den, 1.0), 0.0, 1.0)
    return lines.ya[j] + t * lines.length[j]


def _angle_along(ax, ay, lines: _Lines, y, j=None):
    """The angle from a segment's start A to its point at position y, seen from the origin
    (within (-pi, pi): a segment spans less than half a turn unless it passes the origin)."""
    take = (lambda v: v) if j is None else (lambda v: v[j])
    axj, ayj, tx, ty = take(ax), take(ay), take(lines.tx), take(lines.ty)
    yy = y - take(lines.ya)
    angle = jnp.arctan2(yy * (axj * ty - ayj * tx), axj * axj + ayj * ayj + yy * (axj * tx + ayj * ty))
    return _turn_with_side(angle, 0.5 * np.pi, take(lines.u))


def _turn_with_side(turn, quarter, u):
    """A turn along a line (an angle, or a fraction of the square's perimeter; ``quarter`` a
    quarter turn in its units) with the sign the line's side u gives it when it exceeds a quarter
    turn: a line through the origin to rounding (the centre of a pixel on an outline's line)
    sweeps +-half a turn, and the hard term's angles and the area's sectors must pick the same
    sign there (``_side``). The change is a whole turn or none: the derivative is the turn's own."""
    sg = jax.lax.stop_gradient
    return turn + jnp.where(jnp.abs(sg(turn)) > quarter, _side(u) * jnp.abs(sg(turn)) - sg(turn), 0.0)


def _side(u):
    """+1 where the origin lies on a line's covered side (u < 0: its pieces turn counterclockwise
    about it), else -1. A line within ``_SIDE_TOL`` of the origin (above u's rounding) counts as
    on its lit side: XLA may compute u in several fused kernels whose roundings differ in sign
    when the origin lies on the line (a pixel's centre on the outline), and every use must agree."""
    tol = _SIDE_TOL if u.dtype == jnp.float64 else _SIDE_TOL_32
    return jnp.where(jax.lax.stop_gradient(u) < -tol, 1.0, -1.0)


def _per_point(values, index, n):
    return jax.ops.segment_sum(values, index, num_segments=n)


def _hard_term(ax, ay, lines: _Lines, offset, side_end, cross, cross_change, pair_point, n, dtype, y_cross=None,
               bx=None, by=None):
    """[W(0) >= 1] per point (n,), from the plan's offset and the angles the boundary's pieces
    (statuses, crossings) subtend at the origin."""
    if y_cross is None:
        y_cross = _crossing_along(ax, ay, bx, by, lines, cross)
    cj = cross[:, 0]
    ends = side_end * _angle_along(ax, ay, lines, lines.yb)
    crossings = cross_change * _angle_along(ax, ay, lines, y_cross, cj)
    turns = offset + (_per_point(ends, pair_point, n) - _per_point(crossings, pair_point[cj], n)) / (2.0 * np.pi)
    return jnp.clip(jnp.round(jax.lax.stop_gradient(turns)), 0.0, 1.0).astype(dtype)


def _disk_mass(lines: _Lines, choices, y_cross, hard, n, profile):
    """The light's mass over {W >= 1} within the unit disk (module docstring), per point."""
    pp, cj = choices.pair_point, choices.cross[:, 0]
    h = jnp.abs(lines.u)
    one = jnp.ones_like(h)
    sigma = _side(lines.u)
    ends = sigma * (choices.side_end * _fan(lines.yb, one, h, profile) - choices.side_start * _fan(lines.ya, one, h, profile))
    crossings = sigma[cj] * choices.cross_change * _fan(y_cross, jnp.ones_like(y_cross), h[cj], profile)
    return jnp.clip(hard - (_per_point(ends, pp, n) - _per_point(crossings, pp[cj], n)) / (2.0 * np.pi), 0.0, 1.0)


def _square_sector(qx, qy):
    """The area (in the unit square about the origin) swept from the direction (1/2, -1/2)
    counterclockwise to the direction (qx, qy): a quarter of the perimeter passed."""
    ax_, ay_ = jnp.abs(qx), jnp.abs(qy)
    right = qx >= ay_
    top = (qy > ax_) & ~right
    left = (-qx >= ay_) & ~right & ~top
    # Each side scales by its own coordinate (not max(|qx|, |qy|), whose derivative at a tie, a
    # direction through a corner, is half of each side's): the perimeter's derivative is then
    # the same from both sides of a corner.
    m = 2.0 * jnp.where(right | left, ax_, ay_)
    m = jnp.where(m > 0, m, 1.0)
    X, Y = qx / m, qy / m
    perimeter = jnp.where(right, Y + 0.5, jnp.where(top, 1.5 - X, jnp.where(left, 2.5 - Y, 3.5 + X)))
    return 0.25 * perimeter


def _square_span(ax, ay, lines: _Lines):
    """The positions y along each line where it is inside the unit square: (y_in, y_out), both
    the start's position when it misses."""
    big = jnp.asarray(1e30, ax.dtype)
    lo, hi = -big, big
    for p0, d in ((ax, lines.tx), (ay, lines.ty)):
        flat = d == 0
        dd = jnp.where(flat, 1.0, d)
        t1, t2 = (-0.5 - p0) / dd, (0.5 - p0) / dd
        inside = jnp.abs(p0) <= 0.5
        lo = jnp.where(flat, jnp.where(inside, lo, big), jnp.maximum(lo, jnp.minimum(t1, t2)))
        hi = jnp.where(flat, jnp.where(inside, hi, -big), jnp.minimum(hi, jnp.maximum(t1, t2)))
    misses = lo >= hi
    return lines.ya + jnp.where(misses, 0.0, lo), lines.ya + jnp.where(misses, 0.0, hi)


def pixel_hard_area(ax, ay, bx, by, choices, n):
    """The area of {W >= 1} within each point's pixel (n,), from the boundary's pieces the plan
    found there (``WedgeArrays.pixel_*``); ax.. (P,) the pairs' segments in pixel units (the
    pixel is the unit square about the origin), covered side on the left. By Green's theorem
    about the pixel's centre: [W(0) >= 1] (from the pieces' angles, as ``_hard_term``) plus, for
    each piece from q0 to q1 (clipped to the square), its swept triangle q0 x q1 / 2 less the
    square's sector over the same angle."""
    lines = _lines(ax, ay, bx, by)
    hard = _hard_term(ax, ay, lines, choices.pixel_hard_offset, choices.pixel_side_end, choices.pixel_cross,
                      choices.pixel_cross_change, choices.pair_point, n, ax.dtype, bx=bx, by=by)
    y_in, y_out = _square_span(ax, ay, lines)
    fx, fy = -lines.u * lines.ty, lines.u * lines.tx   # the foot of the perpendicular

    def term(y, j=None):
        take = (lambda v: v) if j is None else (lambda v: v[j])
        k_in, k_out, u, tx, ty, fxx, fyy = (take(v) for v in (y_in, y_out, lines.u, lines.tx, lines.ty, fx, fy))
        yc = jnp.clip(y, k_in, k_out)
        swept = _square_sector(fxx + yc * tx, fyy + yc * ty) - _square_sector(fxx + k_in * tx, fyy + k_in * ty)
        return -0.5 * yc * u - _turn_with_side(swept - jnp.round(jax.lax.stop_gradient(swept)), 0.25, u)

    pp, cross = choices.pair_point, choices.pixel_cross
    ends = choices.pixel_side_end * term(lines.yb) - choices.pixel_side_start * term(lines.ya)
    y = _crossing_along(ax, ay, bx, by, lines, cross)
    crossings = choices.pixel_cross_change * term(y, cross[:, 0])
    return jnp.clip(hard + _per_point(ends, pp, n) - _per_point(crossings, pp[cross[:, 0]], n), 0.0, 1.0)


def _line_share(lines: _Lines, choices, y_cross, scale, profile):
    """Each pair's boundary pieces' share (P,) of its whole line's deficit, for the light of
    radius ``scale`` (P,) sun radii: 1 for a boundary line crossing the light, 0 beyond it."""
    cj = choices.cross[:, 0]
    hs = jnp.abs(lines.u) / scale
    one = jnp.ones_like(hs)
    ends = choices.side_end * _fan(lines.yb / scale, one, hs, profile) \
        - choices.side_start * _fan(lines.ya / scale, one, hs, profile)
    crossings = choices.cross_change * _fan(y_cross / scale[cj], jnp.ones_like(y_cross), hs[cj], profile)
    parts = ends - jax.ops.segment_sum(crossings, cj, num_segments=hs.shape[0])
    whole = 2.0 * np.pi * profile_alpha(hs, profile)
    ok = whole > 0
    return jnp.where(ok, parts / jnp.where(ok, whole, 1.0), 0.0)


def pixel_mean_alpha(points, edge_vertices_world, light, choices, pixel_axes):
    """The hard shadow's area in each point's pixel (n,), from the plan's pixel pieces
    (``WedgeArrays.pixel_*``); pixel_axes (2, 3) or (n, 2, 3)."""
    dtype = points.dtype
    n = points.shape[0]
    pp = choices.pair_point
    ev = edge_vertices_world[choices.pair_edge]
    light = jnp.asarray(light, dtype)
    lt = light if light.ndim == 1 else light[jnp.maximum(pp, 0)]
    axes = jnp.broadcast_to(jnp.asarray(pixel_axes, dtype), (n, 2, 3))[jnp.maximum(pp, 0)]
    choices = _cast(choices, dtype)
    ax, ay, bx, by = pixel_segments(points[jnp.maximum(pp, 0)], ev[:, 0], ev[:, 1], choices.pixel_flip, lt, axes)
    return pixel_hard_area(ax, ay, bx, by, choices, n)


def _cast(choices, dtype):
    """The choices' per-pair and per-crossing flags in ``dtype`` (offsets and indices as they are)."""
    return jax.tree_util.tree_map(lambda x: x.astype(dtype) if jnp.issubdtype(x.dtype, jnp.floating)
                                  else x, choices)


def wedge_alpha(points, edge_vertices_world, light, range_k, choices, profile: str = "disk", pixel_axes=None):
    """Alpha (n,) at points (n, 3): the light's mass behind the mesh (module docstring).

    edge_vertices_world (s, 2, 3): the plan's edges (``wedge_plan.WedgeEdges``); light (3,) or (n, 3);
    range_k: the disk's radius tan r (``disk``; for ``linear``, the light whose straight edge
    gives the linear ramp of that half-width); choices: the plan's ``wedge_plan.WedgeArrays``.
    Points without pairs take [W(0) >= 1] (the plan's hard shadow for them, as ``evaluate``
    does for inactive points).

    pixel_axes (2, 3) or (n, 2, 3): the mean over each pixel (the plan must have been made with
    the same axes): the hard shadow's exact area in the pixel (``pixel_hard_area``) plus, for
    each boundary segment, its straight line's pixel-mean departure from the hard shadow
    (``penumbra.footprint_bump``, exact for one straight edge) times the share of that line's
    deficit its boundary pieces take (``_line_share``, for the light widened by the pixel's reach
    in sun radii). As the pixel shrinks this is the value at the point; as the penumbra narrows
    within the pixel, the hard shadow's area; continuous in between.
    """
    dtype = points.dtype
    n = points.shape[0]
    k = jnp.maximum(jnp.asarray(range_k, dtype), _K_MIN)
    pp, pe = choices.pair_point, choices.pair_edge  # padding pairs: point -1 (their sums are dropped)
    offsets = (choices.hard_offset, choices.pixel_hard_offset)  # kept in float64: rounded to integers
    choices = _cast(choices, dtype)
    choices = dataclasses.replace(choices, hard_offset=offsets[0], pixel_hard_offset=offsets[1])
    ev = edge_vertices_world[pe]
    a, b = ev[:, 0], ev[:, 1]
    light = jnp.asarray(light, dtype)
    lt = light if light.ndim == 1 else light[jnp.maximum(pp, 0)]
    x = points[jnp.maximum(pp, 0)]

    def geometry(xx):
        ax, ay, bx, by = gnomonic_segments(xx, a, b, choices.flip, lt, k)
        lines = _lines(ax, ay, bx, by)
        return lines.u, (ax, ay, bx, by, lines)

    if pixel_axes is None:
        _, (ax, ay, bx, by, lines) = geometry(x)
    else:
        if choices.pixel_side_start is None:
            raise ValueError("a pixel mean of the wedge rule needs a plan made with the pixel's axes")
        axes = jnp.broadcast_to(jnp.asarray(pixel_axes, dtype), (n, 2, 3))[jnp.maximum(pp, 0)]
        u, lin, (ax, ay, bx, by, lines) = jax.linearize(geometry, x, has_aux=True)
        du_a, du_b = lin(axes[:, 0]), lin(axes[:, 1])
    y_cross = _crossing_along(ax, ay, bx, by, lines, choices.cross)
    if pixel_axes is None:
        hard = _hard_term(ax, ay, lines, choices.hard_offset, choices.side_end, choices.cross, choices.cross_change,
                          pp, n, dtype, y_cross)
        return _disk_mass(lines, choices, y_cross, hard, n, profile)
    pax, pay, pbx, pby = pixel_segments(x, a, b, choices.pixel_flip, lt, axes)
    area = pixel_hard_area(pax, pay, pbx, pby, choices, n)
    scale = 1.0 + 0.5 * (jnp.abs(du_a) + jnp.abs(du_b))
    share = _line_share(lines, choices, y_cross, scale, profile)
    bump = footprint_bump(u, du_a, du_b, profile)
    return jnp.clip(area + _per_point(share * bump, pp, n), 0.0, 1.0)
