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

W(0) comes from the plan (``softshadow.wedge_plan``) as an offset F = W(0) - sum_j w_j theta_j
/ 2 pi at the plan's parameters, theta_j the angle segment j subtends at the centre; here
W(0) = round(F + sum_j w_j theta_j / 2 pi) follows the centre across a segment when the sun
or the pose move the segment over it, as long as the far edges' angles change by much less
than half a turn (a move of much less than the distance to them).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

from .penumbra import _fan, footprint_bump, profile_alpha

__all__ = ["boundary_mass", "gnomonic_segments", "pixel_hard_area", "pixel_segments", "wedge_alpha"]

_DEPTH_MIN = 1e-7       # metres in front of the receiver at which segments are clipped
_DEPTH_REL = 1e-6       # ... plus this fraction of the vertex's distance
_K_MIN = 1e-9           # the disk's radius (tan r) is at least this: keeps 1/k finite


def _cross(ax, ay, bx, by):
    return ax * by - ay * bx


def _light_frame(light):
    """Unit s = -L and an orthonormal (e1, e2) spanning the plane perpendicular to it, right-handed
    (e1 x e2 = s); light (3,) or (n, 1, 3). Component tuples. The helper axis (the world axis
    least aligned with the light) is a discrete choice: the results do not depend on the frame's
    rotation about s."""
    sg = jax.lax.stop_gradient
    s = tuple(-light[..., i] for i in range(3))
    mag = jnp.stack([jnp.abs(sg(c)) for c in s], -1)
    pick = jnp.argmin(mag, axis=-1)
    axis = tuple((pick == i).astype(light.dtype) for i in range(3))
    # e1 = axis x s, normalised; e2 = s x e1.
    e1 = (axis[1] * s[2] - axis[2] * s[1], axis[2] * s[0] - axis[0] * s[2], axis[0] * s[1] - axis[1] * s[0])
    norm = jnp.sqrt(e1[0] ** 2 + e1[1] ** 2 + e1[2] ** 2)
    e1 = tuple(c / norm for c in e1)
    e2 = (s[1] * e1[2] - s[2] * e1[1], s[2] * e1[0] - s[0] * e1[2], s[0] * e1[1] - s[1] * e1[0])
    return s, e1, e2


def gnomonic_segments(points, a, b, outward, light, scale=1.0):
    """The segments (a, b) seen from points, in the gnomonic plane of the sun's centre.

    points (n, 3); a, b, outward (n, K, 3): the edges' ends and any vector along their outward
    normal (only its side matters); light (3,) or (n, 3). Returns (ax, ay, bx, by, keep, theta),
    each (n, K): the segment's ends in units of ``scale`` (tan of the angle from the sun's
    centre), oriented so that the edge's covered side (its lit face's) is on the left; keep:
    some of the segment lies in front of the point (the part behind is clipped off at a depth
    of ``_DEPTH_MIN``); theta: the signed angle the segment subtends at the centre, in
    (-pi, pi] (independent of ``scale``). The same arithmetic as ``wedge_plan.subtended_angles``.
    """
    light = jnp.asarray(light)
    lt = light[None, None, :] if light.ndim == 1 else light[:, None, :]
    s, e1, e2 = _light_frame(lt)
    x = tuple(points[:, None, i] for i in range(3))
    wa = tuple(a[..., i] - x[i] for i in range(3))
    wb = tuple(b[..., i] - x[i] for i in range(3))
    da = wa[0] * s[0] + wa[1] * s[1] + wa[2] * s[2]
    db = wb[0] * s[0] + wb[1] * s[1] + wb[2] * s[2]
    na = jnp.sqrt(wa[0] ** 2 + wa[1] ** 2 + wa[2] ** 2)
    nb = jnp.sqrt(wb[0] ** 2 + wb[1] ** 2 + wb[2] ** 2)
    dmin = _DEPTH_MIN + _DEPTH_REL * jnp.maximum(na, nb)
    keep = (da > dmin) | (db > dmin)
    # Clip the part behind dmin off: the end behind moves along the segment to depth dmin.
    step = db - da
    safe = jnp.where(jnp.abs(step) > 0, step, 1.0)
    t = jnp.clip((dmin - da) / safe, 0.0, 1.0)
    cut_a = da < dmin
    cut_b = db < dmin
    ta = jnp.where(cut_a & keep, t, 0.0)
    tb = jnp.where(cut_b & keep, t, 1.0)
    pa = tuple(wa[i] + ta * (wb[i] - wa[i]) for i in range(3))
    pb = tuple(wa[i] + tb * (wb[i] - wa[i]) for i in range(3))
    dpa = jnp.where(keep, da + ta * step, 1.0)
    dpb = jnp.where(keep, da + tb * step, 1.0)
    dot = lambda p, e: p[0] * e[0] + p[1] * e[1] + p[2] * e[2]
    px, py = dot(pa, e1) / dpa, dot(pa, e2) / dpa
    qx, qy = dot(pb, e1) / dpb, dot(pb, e2) / dpb
    # The covered side: opposite the outward normal, seen in the plane. Swap the ends so that
    # it is on the left (a discrete choice).
    sg = jax.lax.stop_gradient
    n1, n2 = dot(tuple(outward[..., i] for i in range(3)), e1), dot(tuple(outward[..., i] for i in range(3)), e2)
    swap = sg(-(qy - py) * n1 + (qx - px) * n2) > 0
    ax, ay = jnp.where(swap, qx, px), jnp.where(swap, qy, py)
    bx, by = jnp.where(swap, px, qx), jnp.where(swap, py, qy)
    theta = jnp.where(keep, jnp.arctan2(_cross(ax, ay, bx, by), ax * bx + ay * by), 0.0)
    inv = 1.0 / scale
    return ax * inv, ay * inv, bx * inv, by * inv, keep, theta


def _intersection_along(ax, ay, bx, by, j, i):
    """Where along segment j (its coordinate y from the foot of the perpendicular) segment i's
    line crosses it, clamped to the segment; slots j, i (n, C) into the (n, K) segments."""
    take = lambda v, q: jnp.take_along_axis(v, q, axis=1)
    axj, ayj, bxj, byj = take(ax, j), take(ay, j), take(bx, j), take(by, j)
    axi, ayi, bxi, byi = take(ax, i), take(ay, i), take(bx, i), take(by, i)
    dxj, dyj, dxi, dyi = bxj - axj, byj - ayj, bxi - axi, byi - ayi
    den = _cross(dxj, dyj, dxi, dyi)
    ok = den != 0
    s = jnp.clip(_cross(axi - axj, ayi - ayj, dxi, dyi) / jnp.where(ok, den, 1.0), 0.0, 1.0)
    length = jnp.sqrt(jnp.maximum(dxj * dxj + dyj * dyj, 0.0))
    ln = jnp.where(length > 0, length, 1.0)
    ya = (axj * dxj + ayj * dyj) / ln
    return jnp.where(ok, ya + s * length, ya)


def boundary_mass(ax, ay, bx, by, winding, side_start, side_end, cross_slots, cross_change,
                  profile: str = "disk"):
    """The light's mass over {W >= 1} within the unit disk, from the boundary's pieces the plan
    found (``wedge_plan.arrangement``): ends (n, K) in sun radii, covered side on the left;
    winding (n,) W at the centre; side_start, side_end (n, K); cross_slots (n, C, 2),
    cross_change (n, C). Returns (n,) in [0, 1]."""
    dx, dy = bx - ax, by - ay
    len2 = dx * dx + dy * dy
    ok = len2 > 0
    length = jnp.sqrt(jnp.where(ok, len2, 1.0))
    tx, ty = jnp.where(ok, dx / length, 1.0), jnp.where(ok, dy / length, 0.0)
    u = ay * tx - ax * ty           # the centre's signed distance to the line (+ on the lit side)
    ya = ax * tx + ay * ty          # the ends' positions along the line from the foot
    yb = ya + jnp.where(ok, length, 0.0)
    h = jnp.abs(u)
    one = jnp.ones_like(ya)
    sigma = jnp.where(jax.lax.stop_gradient(u) < 0, 1.0, -1.0)
    ends = side_end * _fan(yb, one, h, profile) - side_start * _fan(ya, one, h, profile)
    j, i = cross_slots[..., 0], cross_slots[..., 1]
    y = _intersection_along(ax, ay, bx, by, j, i)
    hj = jnp.take_along_axis(h, j, axis=1)
    fans = _fan(y, jnp.ones_like(y), hj, profile)
    inner = jnp.sum(sigma * ends, axis=1) - jnp.sum(jnp.take_along_axis(sigma, j, axis=1) * cross_change * fans,
                                                     axis=1)
    total = (winding >= 0.5).astype(ax.dtype) - inner / (2.0 * np.pi)
    return jnp.clip(total, 0.0, 1.0)


def pixel_segments(points, a, b, outward, light, pixel_axes):
    """The segments' shadows on each pixel's plane, in pixel units (the pixel is the unit square
    about the point): v - x = al a + be b + t s along the sun's direction s, a and b the pixel's
    sides (pixel_axes (n, 2, 3)). Returns (ax, ay, bx, by, keep), each (n, K), oriented with the
    covered side on the left (mirrored axes are swapped); the part on the far side of the plane
    from the sun (t < 0) is clipped off. The arithmetic of ``wedge_plan.arrangement``."""
    sg = jax.lax.stop_gradient
    s = tuple(-light[..., i] for i in range(3))
    s = tuple(c[:, None] if c.ndim == 1 else c for c in s)
    A = tuple(pixel_axes[:, 0, i][:, None] for i in range(3))
    B = tuple(pixel_axes[:, 1, i][:, None] for i in range(3))
    cross = lambda u, v: (u[1] * v[2] - u[2] * v[1], u[2] * v[0] - u[0] * v[2], u[0] * v[1] - u[1] * v[0])
    dot = lambda u, v: u[0] * v[0] + u[1] * v[1] + u[2] * v[2]
    c_bs, c_sa, c_ab = cross(B, s), cross(s, A), cross(A, B)
    det = dot(A, c_bs)
    det = jnp.where(det == 0, 1.0, det)
    flip = sg(det) < 0
    x = tuple(points[:, None, i] for i in range(3))
    wa = tuple(a[..., i] - x[i] for i in range(3))
    wb = tuple(b[..., i] - x[i] for i in range(3))
    ta, tb = dot(c_ab, wa) / det, dot(c_ab, wb) / det
    keep = (ta > 0) | (tb > 0)
    den = jnp.where(ta - tb == 0, 1.0, ta - tb)
    t_lo = jnp.where(ta < 0, ta / den, 0.0)
    t_hi = jnp.where((ta >= 0) & (tb < 0), ta / den, 1.0)
    pa, pb = dot(c_bs, wa) / det, dot(c_sa, wa) / det
    qa, qb = dot(c_bs, wb) / det, dot(c_sa, wb) / det
    px, py = pa + t_lo * (qa - pa), pb + t_lo * (qb - pb)
    qx, qy = pa + t_hi * (qa - pa), pb + t_hi * (qb - pb)
    px, py = jnp.where(flip, py, px), jnp.where(flip, px, py)
    qx, qy = jnp.where(flip, qy, qx), jnp.where(flip, qx, qy)
    out = tuple(outward[..., i] for i in range(3))
    n1, n2 = dot(c_bs, out) / det, dot(c_sa, out) / det
    n1, n2 = jnp.where(flip, n2, n1), jnp.where(flip, n1, n2)
    swap = sg((qx - px) * n2 - (qy - py) * n1) > 0
    ax, ay = jnp.where(swap, qx, px), jnp.where(swap, qy, py)
    bx, by = jnp.where(swap, px, qx), jnp.where(swap, py, qy)
    return ax, ay, bx, by, keep


def _square_sector(qx, qy):
    """The area (in the unit square about the origin) swept from the direction (1/2, -1/2)
    counterclockwise to the direction (qx, qy): a quarter of the perimeter passed."""
    ax_, ay_ = jnp.abs(qx), jnp.abs(qy)
    m = jnp.maximum(ax_, ay_)
    m = jnp.where(m > 0, 2.0 * m, 1.0)
    X, Y = qx / m, qy / m
    right = qx >= ay_
    top = (qy > ax_) & ~right
    left = (-qx >= ay_) & ~right & ~top
    perimeter = jnp.where(right, Y + 0.5, jnp.where(top, 1.5 - X, jnp.where(left, 2.5 - Y, 3.5 + X)))
    return 0.25 * perimeter


def _square_span(ax, ay, tx, ty, ya):
    """The positions y along each line (y from the foot of the perpendicular, the line through
    A with direction t) where it is inside the unit square: (y_in, y_out), y_in > y_out when it
    misses."""
    big = jnp.asarray(1e30, ax.dtype)
    lo, hi = -big, big
    for p0, d in ((ax, tx), (ay, ty)):
        flat = d == 0
        dd = jnp.where(flat, 1.0, d)
        t1, t2 = (-0.5 - p0) / dd, (0.5 - p0) / dd
        tmin, tmax = jnp.minimum(t1, t2), jnp.maximum(t1, t2)
        inside = jnp.abs(p0) <= 0.5
        lo = jnp.where(flat, jnp.where(inside, lo, big), jnp.maximum(lo, tmin))
        hi = jnp.where(flat, jnp.where(inside, hi, -big), jnp.minimum(hi, tmax))
    return ya + lo, ya + hi


def pixel_hard_area(ax, ay, bx, by, winding, side_start, side_end, cross_slots, cross_change):
    """The area of {W >= 1} within the unit square about the origin (the pixel), from the
    boundary's pieces the plan found in the pixel (``WedgeArrays.pixel_*``): ends (n, K) in pixel
    units, covered side on the left; winding (n,). By Green's theorem about the pixel's centre:
    [W(0) >= 1] plus, for each piece from q0 to q1 (clipped to the square), its swept triangle
    q0 x q1 / 2 less the square's sector over the same angle. Returns (n,) in [0, 1]."""
    dx, dy = bx - ax, by - ay
    len2 = dx * dx + dy * dy
    ok = len2 > 0
    length = jnp.sqrt(jnp.where(ok, len2, 1.0))
    tx, ty = jnp.where(ok, dx / length, 1.0), jnp.where(ok, dy / length, 0.0)
    u = ay * tx - ax * ty
    ya = ax * tx + ay * ty
    yb = ya + jnp.where(ok, length, 0.0)
    y_in, y_out = _square_span(ax, ay, tx, ty, ya)
    misses = y_in >= y_out
    y_in = jnp.where(misses, ya, y_in)
    y_out = jnp.where(misses, ya, y_out)
    fx, fy = -u * ty, u * tx                       # the foot of the perpendicular: A - (A . t) t

    def term(y, k_in, k_out, uu, fxx, fyy, txx, tyy):
        yc = jnp.clip(y, k_in, k_out)
        swept = _square_sector(fxx + yc * txx, fyy + yc * tyy) - _square_sector(fxx + k_in * txx, fyy + k_in * tyy)
        return -0.5 * yc * uu - (swept - jnp.round(swept))

    ends = side_end * term(yb, y_in, y_out, u, fx, fy, tx, ty) - side_start * term(ya, y_in, y_out, u, fx, fy, tx, ty)
    j, i = cross_slots[..., 0], cross_slots[..., 1]
    y = _intersection_along(ax, ay, bx, by, j, i)
    take = lambda v: jnp.take_along_axis(v, j, axis=1)
    crossings = cross_change * term(y, take(y_in), take(y_out), take(u), take(fx), take(fy), take(tx), take(ty))
    total = (winding >= 0.5).astype(ax.dtype) + jnp.sum(ends, axis=1) - jnp.sum(crossings, axis=1)
    return jnp.clip(total, 0.0, 1.0)


def _line_share(ya, yb, y_cross, h, scale, side_start, side_end, cross_slots, cross_change, profile):
    """Each segment's boundary pieces' share (n, K) of its whole line's deficit, for a light of
    radius ``scale`` (n, K) sun radii: 1 for a boundary line crossing the light, 0 beyond it."""
    one = jnp.ones_like(ya)
    hs = h / scale
    ends = side_end * _fan(yb / scale, one, hs, profile) - side_start * _fan(ya / scale, one, hs, profile)
    j = cross_slots[..., 0]
    take = lambda v: jnp.take_along_axis(v, j, axis=1)
    fans = cross_change * _fan(y_cross / take(scale), jnp.ones_like(y_cross), take(hs), profile)
    # Scatter each crossing's fan onto its segment j (a one-hot sum: C and K are small).
    per_segment = jnp.sum(fans[..., None] * (j[..., None] == jnp.arange(ya.shape[1])), axis=1)
    whole = 2.0 * np.pi * profile_alpha(hs, profile)
    ok = whole > 0
    return jnp.where(ok, (ends - per_segment) / jnp.where(ok, whole, 1.0), 0.0)


def wedge_alpha(points, edge_ids, edge_vertices_world, outward_sign, jump, light, range_k,
                choices, profile: str = "disk", pixel_axes=None):
    """Alpha (n,) at points (n, 3): the light's mass behind the mesh (module docstring).

    edge_ids (n, K) candidate edges (-1: none; the plan's: every silhouette edge whose segment
    may meet the disk), edge_vertices_world (s, 2, 3), outward_sign (s,), jump (s,) W's change
    across each edge; light (3,) or (n, 3); range_k: the disk's radius tan r (``disk``; for
    ``linear``, the light whose straight edge gives the linear ramp of that half-width);
    choices: the plan's ``wedge_plan.WedgeArrays``.

    pixel_axes (2, 3) or (n, 2, 3): the mean over each pixel (the plan must have been made with
    the same axes): the hard shadow's exact area in the pixel (``pixel_hard_area``) plus, for
    each boundary segment, its straight line's pixel-mean departure from the hard shadow
    (``penumbra.footprint_bump``, exact for one straight edge) times the share of that line's
    deficit its boundary pieces take (``_line_share``, for the light widened by the pixel's reach
    in sun radii). As the pixel shrinks this is the value at the point; as the penumbra
    narrows within the pixel, the hard shadow's area; continuous in between, where pieces or
    the nearest edge change.
    """
    dtype = points.dtype
    k = jnp.maximum(jnp.asarray(range_k, dtype), _K_MIN)
    safe = jnp.maximum(edge_ids, 0)
    ev = edge_vertices_world[safe]                      # (n, K, 2, 3)
    a, b = ev[..., 0, :], ev[..., 1, :]
    light = jnp.asarray(light, dtype)
    lt = light if light.ndim == 1 else light[:, None, :]
    tvec = b - a
    cvec = jnp.stack([tvec[..., 1] * lt[..., 2] - tvec[..., 2] * lt[..., 1],
                      tvec[..., 2] * lt[..., 0] - tvec[..., 0] * lt[..., 2],
                      tvec[..., 0] * lt[..., 1] - tvec[..., 1] * lt[..., 0]], -1)
    outward = outward_sign[safe][..., None] * cvec
    used = (edge_ids >= 0) & (jump[safe] > 0)
    if pixel_axes is None:
        ax, ay, bx, by, keep, theta = gnomonic_segments(points, a, b, outward, light, k)
        w = jnp.where(keep & used, jump[safe], 0.0).astype(dtype)
        winding = jnp.round(jax.lax.stop_gradient(choices.winding + jnp.sum(w * theta, axis=1) / (2.0 * np.pi)))
        return boundary_mass(ax, ay, bx, by, winding, choices.side_start.astype(dtype),
                             choices.side_end.astype(dtype), choices.cross_slots, choices.cross_change.astype(dtype),
                             profile)
    if choices.pixel_side_start is None:
        raise ValueError("a pixel mean of the wedge rule needs a plan made with the pixel's axes")
    axes = jnp.broadcast_to(jnp.asarray(pixel_axes, dtype), (points.shape[0], 2, 3))

    def line_geometry(xx):
        ax, ay, bx, by, keep, theta = gnomonic_segments(xx, a, b, outward, light, k)
        dx, dy = bx - ax, by - ay
        len2 = dx * dx + dy * dy
        ln = jnp.sqrt(jnp.where(len2 > 0, len2, 1.0))
        u = (ay * dx - ax * dy) / ln
        return u, (ax, ay, bx, by, keep, theta)

    u, lin, (ax, ay, bx, by, keep, theta) = jax.linearize(line_geometry, points, has_aux=True)
    du_a, du_b = lin(axes[:, 0]), lin(axes[:, 1])
    w = jnp.where(keep & used, jump[safe], 0.0).astype(dtype)
    winding = jnp.round(jax.lax.stop_gradient(choices.winding + jnp.sum(w * theta, axis=1) / (2.0 * np.pi)))
    # The hard shadow's area in the pixel.
    pax, pay, pbx, pby, _ = pixel_segments(points, a, b, outward, light, axes)
    area = pixel_hard_area(pax, pay, pbx, pby, winding, choices.pixel_side_start.astype(dtype),
                           choices.pixel_side_end.astype(dtype), choices.pixel_cross_slots,
                           choices.pixel_cross_change.astype(dtype))
    # Each boundary line's penumbra, over the pixel, by its pieces' share.
    dx, dy = bx - ax, by - ay
    len2 = dx * dx + dy * dy
    ln = jnp.sqrt(jnp.where(len2 > 0, len2, 1.0))
    ya = (ax * dx + ay * dy) / ln
    yb = ya + jnp.where(len2 > 0, ln, 0.0)
    y_cross = _intersection_along(ax, ay, bx, by, choices.cross_slots[..., 0], choices.cross_slots[..., 1])
    scale = 1.0 + 0.5 * (jnp.abs(du_a) + jnp.abs(du_b))
    share = _line_share(ya, yb, y_cross, jnp.abs(u), scale, choices.side_start.astype(dtype),
                        choices.side_end.astype(dtype), choices.cross_slots, choices.cross_change.astype(dtype),
                        profile)
    bump = footprint_bump(u, du_a, du_b, profile)
    return jnp.clip(area + jnp.sum(share * bump, axis=1), 0.0, 1.0)
