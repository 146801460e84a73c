"""The Shoji paper's own algorithm (the benchmark's baseline): its stencil, texture states,
neighbourhood test, alpha and the grid-search fit of its range."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from softshadow import GroundGrid, Pose, ShadowParams, SoftShadowModel, Sun
from benchmarks.meshes import bench_mesh
from benchmarks.paper import fit_shoji, predicted_range_px
from benchmarks.shoji import ShojiRenderer
from benchmarks.scenes import scene_grid


def _sun(az, el):
    """Unit vector towards the sun (docs/formats.md)."""
    return -np.asarray(Sun(az, el).light_np)


@pytest.mark.parametrize("name,az,el", [("pillar", 200.0, 40.0), ("ball", 130.0, 55.0)])
def test_stencil_count_is_the_hard_shadow_of_the_renderer(name, az, el):
    # With no expansion the counted volume is the hard shadow: the same pixel centres as the
    # project's renderer at k = 0, point-sampled (with the footprint, an outline pixel at k = 0
    # reads the hard shadow's area in it; counts of 0 or 1 on these convex shapes, never negative).
    mesh = bench_mesh(name)
    s = _sun(az, el)
    grid = scene_grid(mesh, s, 96)
    stencil = ShojiRenderer(mesh).stencil(s, grid, 0.0)
    hard = np.asarray(SoftShadowModel.from_mesh(mesh, footprint=False).ground_map(ShadowParams(0.0, 0.0), Sun(az, el), Pose(), grid)) < 0.5
    assert set(np.unique(stencil)) <= {0, 1}
    assert np.array_equal(stencil >= 1, hard)


@pytest.mark.parametrize("name", ["ball", "dragon"])
def test_expansion_grows_the_volume(name):
    mesh = bench_mesh(name)
    s = _sun(200.0, 40.0)
    grid = scene_grid(mesh, s, 96)
    r = ShojiRenderer(mesh)
    st0, st1 = r.stencil(s, grid, 0.0), r.stencil(s, grid, 0.02)
    assert st0.min() >= 0 and st1.min() >= 0
    assert np.all((st1 >= 1) | ~(st0 >= 1)) and (st1 >= 1).sum() > 1.1 * (st0 >= 1).sum()
    if name == "dragon":
        assert st0.max() >= 2  # parts of the dragon that shadow the same ground count twice


def _slab_texture(range_px):
    # A long low wall, sun from the west: the shadow runs east (+col), intensity rising with col.
    wall = trimesh.creation.box(extents=(0.1, 2.0, 1.0))
    wall.apply_translation([0.0, 0.0, 0.5])
    s = _sun(270.0, 30.0)
    grid = GroundGrid.around((1.0, 0.0), 4.0, 80)
    r = ShojiRenderer(wall)
    st = r.stencil(s, grid, 0.0)
    return r.texture(st, s, range_px), st


def test_states_intensity_and_neighbourhood_test():
    tex, st = _slab_texture(6)
    assert set(np.unique(tex.state)) == {-1, 1, 2}
    shadow = st >= 1
    assert np.array_equal(tex.state != -1, shadow)  # soft shadow only inside the shadow section
    rows, cols = np.nonzero(shadow)
    # Intensity: 0 at the quadrilateral's start (next to the wall), the range at its end, -1 outside.
    assert tex.intensity[rows, cols.min()].max() == 0 and tex.intensity[rows, cols.max()].min() == 6
    assert tex.intensity[0, 0] == -1
    # P(i +- I, j +- I): at the far end the soft band reaches I pixels in from the outline.
    mid = (rows.min() + rows.max()) // 2
    far = tex.state[mid, cols.min():cols.max() + 1]
    assert np.sum(far[-10:] == 2) == 7  # the outline pixel (I = 6) and six neighbours in
    # Near the wall the intensity is 0: the neighbourhood is the outline pixel alone, so the
    # soft band is one pixel and the next one in is hard.
    assert tex.state[mid, cols.min()] == 2 and tex.state[mid, cols.min() + 1] == 1
    # Alpha: 1 in the hard shadow, 0 outside, strictly between on the soft band, rising inwards.
    a = tex.alpha[mid, cols.min():cols.max() + 1]
    soft = far == 2
    assert np.all((a[soft] > 0) & (a[soft] < 1)) and np.all(np.diff(a[-8:]) <= 0)
    assert np.all(tex.alpha[tex.state == 1] == 1) and np.all(tex.alpha[tex.state == -1] == 0)


def test_range_zero_is_the_hard_shadow():
    tex, st = _slab_texture(0)
    assert np.array_equal(tex.alpha, (st >= 1).astype(float))


def test_fit_recovers_the_algorithms_own_parameters():
    mesh = bench_mesh("pillar")
    s = _sun(200.0, 40.0)
    grid = scene_grid(mesh, s, 96)
    r = ShojiRenderer(mesh)
    observed = 0.7 * r.render(s, grid, 5.0, 0.3, expand=0.004)
    keep = np.ones(observed.shape, bool)
    fit = fit_shoji(r, s, grid, observed, keep, ranges=(0, 3, 5, 8), expands=(0.0, 0.004, 0.008))
    assert (fit["range_px"], fit["expand"]) == (5.0, 0.004)
    assert fit["rho"] == pytest.approx(0.3, abs=1e-6) and fit["lit"] == pytest.approx(0.7, abs=1e-6)


def test_predicted_range_is_the_models_penumbra_at_the_tip_in_pixels():
    # 2 k h / sin^2(E) metres along the ground at the tip: k 0.005, h 3 m, E 30 deg -> 0.12 m.
    assert predicted_range_px(0.005, 3.0, 30.0, 0.01) == pytest.approx(12.0)
