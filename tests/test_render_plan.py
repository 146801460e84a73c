"""The plan's fast paths against their plain counterparts (NumPy, no JAX gradients).

The plan (silhouette, winding fill, candidate edges) takes shortcuts for speed:
closed meshes skip the general edge-face bookkeeping, collinear merges start
from pairs cached on the occluder, the winding fill sums rows through an
integral image, candidates are picked greedily. Each is checked here against a
direct computation of the same thing.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from softshadow.meshes import builtin_mesh
from softshadow.occluder import Occluder, merge_collinear, silhouette
from softshadow.posed import pose_matrix
from softshadow.raster import candidate_labels, winding_at_points, winding_fill


def light_from(azimuth_deg: float, elevation_deg: float) -> np.ndarray:
    a, e = np.radians(azimuth_deg), np.radians(elevation_deg)
    return -np.array([np.sin(a) * np.cos(e), np.cos(a) * np.cos(e), np.sin(e)])


@pytest.mark.parametrize("seed", range(6))
def test_winding_fill_equals_its_pointwise_twin(seed):
    """Random weighted loops (overlapping, so winding numbers of 2 and holes occur)."""
    rng = np.random.default_rng(seed)
    starts, ends, weights = [], [], []
    for _ in range(3):
        n = rng.integers(3, 9)
        loop = rng.uniform(-4.0, 36.0, (n, 2))
        starts.append(loop)
        ends.append(np.roll(loop, -1, axis=0))
        weights.append(np.full(n, rng.choice([1.0, -1.0, 2.0])))
    start, end, weight = np.concatenate(starts), np.concatenate(ends), np.concatenate(weights)
    filled = winding_fill((30, 33), start, end, weight)
    rows, cols = np.mgrid[0:30, 0:33]
    centres = np.stack([cols.ravel(), rows.ravel()], 1).astype(float)
    np.testing.assert_array_equal(filled.ravel(), winding_at_points(centres, start, end, weight))


@pytest.mark.parametrize("seed", range(4))
def test_layer_count_fill_sums_the_layers_absolute_winding_counts(seed):
    """Two layers of random weighted loops (winding counts of either sign, 2 and holes): the
    compiled sum of their absolute counts is each layer's pointwise count, made absolute, summed."""
    from softshadow.raster import layer_count_fill, winding_count_at_points
    rng = np.random.default_rng(100 + seed)
    px, layers, want = np.zeros((0, 2)), [], np.zeros(30 * 33)
    rows, cols = np.mgrid[0:30, 0:33]
    centres = np.stack([cols.ravel(), rows.ravel()], 1).astype(float)
    for _ in range(2):
        edges, weights = [], []
        for _ in range(3):
            n = int(rng.integers(3, 9))
            first = len(px)
            px = np.vstack([px, rng.uniform(-4.0, 36.0, (n, 2))])
            edges.append(np.stack([np.arange(first, first + n), np.roll(np.arange(first, first + n), -1)], 1))
            weights.append(np.full(n, rng.choice([1.0, -1.0, 2.0])))
        e, w = np.concatenate(edges), np.concatenate(weights)
        layers.append((e, w))
        want += np.abs(winding_count_at_points(centres, px[e[:, 0]], px[e[:, 1]], w))
    got = layer_count_fill((30, 33), px, layers)
    assert got.dtype == np.float32 and got.shape == (30, 33)
    assert (want > 1).any() and (want == 0).any()
    np.testing.assert_array_equal(got.ravel(), want)


def _general_path(occ: Occluder) -> Occluder:
    """The same occluder taking the general (open-mesh) branches of ``silhouette``."""
    twin = dataclasses.replace(occ, watertight=False)
    twin.__dict__["two_faced"] = False  # a cached property: preset it
    return twin


@pytest.mark.parametrize("mesh", ["pillar", "ball", "dragon"])
@pytest.mark.parametrize("azimuth,elevation,rot", [(200.0, 40.0, 0.0), (33.0, 71.0, 25.0), (290.0, 12.0, -60.0)])
def test_closed_mesh_silhouette_equals_the_general_path(mesh, azimuth, elevation, rot):
    occ = Occluder.from_trimesh(builtin_mesh(mesh))
    rotation = pose_matrix([0.0, 0.0, rot])
    world = occ.vertices @ rotation.T
    light = light_from(azimuth, elevation)
    fast = silhouette(occ, world, rotation, light)
    slow = silhouette(_general_path(occ), world, rotation, light)
    np.testing.assert_array_equal(fast.vertex_ids, slow.vertex_ids)
    np.testing.assert_array_equal(fast.outward_sign, slow.outward_sign)
    np.testing.assert_allclose(fast.paper_normal_local, slow.paper_normal_local, atol=1e-12)
    np.testing.assert_allclose(fast.normal_local, slow.normal_local, atol=1e-12)
    # The lit faces' boundary is the same oriented edge set (the general path adds a second
    # layer, the unlit faces, which for a closed mesh covers the same shadow).
    np.testing.assert_array_equal(fast.fill_edges[0][0], slow.fill_edges[0][0])
    np.testing.assert_array_equal(fast.fill_edges[0][1], slow.fill_edges[0][1])


@pytest.mark.parametrize("azimuth", [0.0, 30.0, 124.0])
def test_collinear_merge_from_cached_pairs_equals_the_search(azimuth):
    """The pillar's subdivided side edges: merging from the occluder's cached collinear pairs
    gives what merging from a search over all silhouette vertices gives."""
    occ = Occluder.from_trimesh(builtin_mesh("pillar"))
    assert len(occ.collinear_pairs)
    rotation = np.eye(3)
    light = light_from(azimuth, 40.0)
    sil = silhouette(occ, occ.vertices, rotation, light)
    twin = dataclasses.replace(occ)
    twin.__dict__["collinear_pairs"] = np.zeros((0, 3), np.int64)  # no merging
    raw = silhouette(twin, occ.vertices, rotation, light)
    assert len(raw.vertex_ids) > len(sil.vertex_ids)
    ids, sign, paper = merge_collinear(raw.vertex_ids, occ.vertices, light, raw.outward_sign,
                                       raw.paper_normal_local)
    np.testing.assert_array_equal(ids, sil.vertex_ids)
    np.testing.assert_array_equal(sign, sil.outward_sign)
    np.testing.assert_allclose(paper, sil.paper_normal_local)


def test_candidates_are_distinct_and_nearest_first():
    rng = np.random.default_rng(3)
    label = rng.integers(0, 12, (40, 40)).astype(np.int32)
    label[:, :20] = 3  # a large cell, so many rows have few distinct labels
    neighbours = rng.integers(-1, 12, (12, 2))
    rows, cols = np.mgrid[0:40, 0:40]
    rows, cols = rows.ravel(), cols.ravel()
    k = 5
    got = candidate_labels(label, rows, cols, radii=(2, 6), max_candidates=k, neighbours=neighbours)
    offsets = [(dr * r, dc * r) for r in (2, 6) for dr in (-1, 0, 1) for dc in (-1, 0, 1) if (dr, dc) != (0, 0)]
    for i, (r, c) in enumerate(zip(rows, cols)):
        first = label[r, c]
        samples = [first, *neighbours[first]]
        samples += [label[min(max(r + dr, 0), 39), min(max(c + dc, 0), 39)] for dr, dc in offsets]
        expected = [first]
        for s in samples[1:]:
            if s >= 0 and s not in expected and len(expected) < k:
                expected.append(s)
        expected += [first] * (k - len(expected))
        assert list(got[i]) == expected, (r, c)
