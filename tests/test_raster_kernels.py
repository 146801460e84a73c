"""The light-space raster's compiled loops against plain references.

- ``draw_segment_labels`` against the NumPy array program it replaces (the same clipping, the
  same samples, later segments winning), over random segments, off-frame and degenerate ones
  included: the same image, bit for bit.
- ``_end_neighbours`` against a direct reference: the same neighbours.
- ``_chamfer_kernel`` (the distance transform near the outline) against OpenCV's
  ``distanceTransformWithLabels`` (L2, 5 x 5 mask, a label per seed pixel) on random images,
  over the whole window, and windows of them: the same distances and the same nearest seed, ties
  included. Its tiles left out far from the seeds are tested on real rasters
  (tests/test_raster_window.py).
- ``_seeds_kernel`` against the OpenCV morphology it replaces (the 3 x 3 dilation of the
  dilation minus the erosion of the hard shadow) on random rasters, thin and all-one included:
  the same seeds.
"""

from __future__ import annotations

import cv2
import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from softshadow.raster import _chamfer_kernel, _end_neighbours, _seeds_kernel, draw_segment_labels


def labels_reference(shape, start, end, values):
    """The segments' label image as array operations."""
    with np.errstate(all="ignore"):  # non-finite segments are dropped at the end, as in the loop
        return _labels_reference(shape, start, end, values)


def _labels_reference(shape, start, end, values):
    h, w = shape
    label = np.zeros((h, w), np.int32)
    x0, y0, x1, y1 = start[:, 0], start[:, 1], end[:, 0], end[:, 1]
    t0, t1 = np.zeros(len(start)), np.ones(len(start))
    for p0, d, hi in ((x0, x1 - x0, float(w)), (y0, y1 - y0, float(h))):
        ta, tb = (-1.0 - p0) / d, (hi - p0) / d
        flat = d == 0
        outside = flat & ((p0 < -1.0) | (p0 > hi))
        t0 = np.where(flat, t0, np.maximum(t0, np.minimum(ta, tb)))
        t1 = np.where(flat | outside, np.where(outside, -1.0, t1), np.minimum(t1, np.maximum(ta, tb)))
    idx = np.flatnonzero((t1 >= t0) & np.isfinite(x0 + y0 + x1 + y1))
    if not len(idx):
        return label
    dx, dy = (x1 - x0)[idx], (y1 - y0)[idx]
    ax, ay = x0[idx] + t0[idx] * dx, y0[idx] + t0[idx] * dy
    span = t1[idx] - t0[idx]
    bx, by = dx * span, dy * span
    n = np.ceil(2.0 * np.hypot(bx, by)).astype(np.int64) + 1
    seg = np.repeat(np.arange(len(idx)), n)
    step = np.arange(len(seg)) - np.repeat(np.cumsum(n) - n, n)
    frac = step / np.maximum(n - 1, 1)[seg]
    col = np.rint(ax[seg] + frac * bx[seg]).astype(np.int64)
    row = np.rint(ay[seg] + frac * by[seg]).astype(np.int64)
    ok = (col >= 0) & (col < w) & (row >= 0) & (row < h)
    label.reshape(-1)[row[ok] * w + col[ok]] = values[idx][seg[ok]]
    return label


coordinate = st.one_of(st.floats(-30.0, 90.0), st.sampled_from([-1.0, -0.5, 0.0, 0.5, 59.5, 60.0, np.nan, np.inf]))


@settings(deadline=None)
@given(st.lists(st.tuples(coordinate, coordinate, coordinate, coordinate), max_size=40),
       st.integers(1, 60), st.integers(1, 60), st.booleans())
def test_segment_labels_are_the_array_programs(segments, h, w, repeat_ends):
    seg = np.array(segments, np.float64).reshape(-1, 4)
    if repeat_ends and len(seg):
        seg[::3, 2:] = seg[::3, :2]  # points: zero-length segments
    start, end = seg[:, :2], seg[:, 2:]
    values = np.arange(7, 7 + len(seg))
    np.testing.assert_array_equal(draw_segment_labels((h, w), start, end, values),
                                  labels_reference((h, w), start, end, values))


def neighbours_reference(ids, keep):
    """For each kept edge's ends, the lowest-numbered other kept edge at that vertex."""
    out = -np.ones((len(ids), 2), np.int64)
    kept = np.flatnonzero(keep)
    for e in kept:
        for j in (0, 1):
            others = [f for f in kept if f != e and ids[e, j] in ids[f]]
            out[e, j] = others[0] if others else -1
    return out


edge = st.tuples(st.integers(0, 12), st.integers(0, 12), st.booleans()).filter(lambda e: e[0] != e[1])


@settings(deadline=None)
@given(st.lists(edge, max_size=30))
def test_end_neighbours_are_the_lowest_other_kept_edge(edges):
    """Edges between two vertices (a silhouette's)."""
    ids = np.array([e[:2] for e in edges], np.int64).reshape(-1, 2)
    keep = np.array([e[2] for e in edges], bool)
    np.testing.assert_array_equal(_end_neighbours(ids, keep), neighbours_reference(ids, keep))


@settings(deadline=None)
@given(st.integers(1, 70), st.integers(1, 70), st.floats(0.0005, 0.3), st.integers(0, 2 ** 32 - 1),
       st.integers(1, 12), st.integers(0, 150))
def test_chamfer_transform_is_opencvs(h, w, seed_fraction, seed, tile, reach):
    """Within ``reach`` of a seed, OpenCV's distance and nearest seed; beyond it, farther."""
    rng = np.random.default_rng(seed)
    src = (rng.random((h, w)) >= seed_fraction).astype(np.uint8)
    src[rng.integers(h), rng.integers(w)] = 0  # at least one seed
    edge_of_seed = rng.integers(0, 5, int(np.count_nonzero(src == 0)))
    label_img = np.zeros((h, w), np.int32)
    label_img[src == 0] = edge_of_seed + 1
    seed_rc = np.stack(np.nonzero(src == 0), 1).astype(np.int64)
    # A window of rows and columns, its seeds those of its rows (all of them in its columns here).
    a, b = sorted(rng.integers(0, h + 1, 2))
    b = max(b, a + 1)
    rows_in = (seed_rc[:, 0] >= a) & (seed_rc[:, 0] < b)
    if not rows_in.any():
        a, b = 0, h
        rows_in[:] = True
    dist = np.full((h, w), np.inf, np.float32)
    label = np.full((h, w), -1, np.int32)
    _chamfer_kernel()(src, label_img, seed_rc[rows_in], a, b, 0, w, a, b, reach, tile, dist, label)
    want, nearest = cv2.distanceTransformWithLabels(src[a:b], cv2.DIST_L2, cv2.DIST_MASK_5,
                                                    labelType=cv2.DIST_LABEL_PIXEL)
    within = want <= reach
    np.testing.assert_array_equal(dist[a:b][within], want[within])
    np.testing.assert_array_equal(label[a:b][within], np.concatenate([[-1], edge_of_seed[rows_in]])[nearest][within])
    assert np.all(dist[a:b][~within] > reach)
    assert np.all(np.isinf(dist[:a])) and np.all(np.isinf(dist[b:]))


@settings(deadline=None)
@given(st.integers(1, 40), st.integers(1, 40), st.floats(0.0, 1.0), st.floats(0.0, 1.0), st.integers(0, 2 ** 32 - 1))
def test_seeds_are_the_labelled_pixels_of_opencvs_boundary_band(h, w, shadow_fraction, label_fraction, seed):
    """The seeds: labelled pixels where cv2.dilate(dilate(hard) - erode(hard)) (3 x 3, replicated
    border inside) is set, in row-major order, with the rows' counts and the columns' span."""
    rng = np.random.default_rng(seed)
    # Blobs (a coarse random image scaled up) and single pixels: runs and isolated values both.
    coarse = rng.random(((h + 3) // 4, (w + 3) // 4)) < shadow_fraction
    hard = np.kron(coarse, np.ones((4, 4), bool))[:h, :w].copy()
    hard ^= rng.random((h, w)) < 0.02
    hard = hard.view(np.uint8)
    label = np.where(rng.random((h, w)) < label_fraction, rng.integers(1, 9, (h, w)), 0).astype(np.int32)
    src = np.empty((h, w), np.uint8)
    before = np.empty(h + 1, np.int64)
    cols = np.empty(2, np.int64)
    seed_rc = _seeds_kernel()(hard, label, src, before, cols)

    kernel = np.ones((3, 3), np.uint8)
    band = cv2.dilate(cv2.dilate(hard, kernel, borderType=cv2.BORDER_REPLICATE)
                      - cv2.erode(hard, kernel, borderType=cv2.BORDER_REPLICATE), kernel)
    want = (band > 0) & (label > 0)
    np.testing.assert_array_equal(src, np.where(want, 0, 1))
    np.testing.assert_array_equal(seed_rc, np.argwhere(want))
    np.testing.assert_array_equal(before, np.concatenate([[0], np.cumsum(want.sum(1))]))
    if want.any():
        assert (cols[0], cols[1]) == (np.flatnonzero(want.any(0))[0], np.flatnonzero(want.any(0))[-1])
