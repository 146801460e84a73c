"""The light-space raster's distance transform near the outline only (``rasterise_shadow(...,
exact_px=...)``, as ``plan_dense_points`` runs it for ``render_frame``).

Where the whole raster's boundary distance is at most ``exact_px``, the distance and the
governing edge are the whole raster's, bit for bit; elsewhere the distance is larger (what the
plan needs to skip those pixels). Over meshes, poses, suns, pixel sizes and exact_px
(hypothesis), in one window and in two halves, one on a second thread; and the scene's plan is
``plan_points``' (tests/test_scene_frame.py). The whole raster's transform (the same compiled
passes with no window) is OpenCV's ``distanceTransformWithLabels`` from the same seeds.
"""

from __future__ import annotations

import functools
from concurrent.futures import ThreadPoolExecutor

import cv2
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from benchmarks.meshes import mit_dragon
from softshadow import GroundGrid, Pose, SoftShadowModel, Sun, decimate
from softshadow.meshes import builtin_mesh
from softshadow.posed import PosedOccluder
from softshadow import raster
from softshadow.raster import rasterise_shadow


@functools.cache
def occluder(name: str):
    mesh = decimate(mit_dragon(full=True), 300) if name == "dragon-300" else builtin_mesh(name)
    return SoftShadowModel.from_mesh(mesh).occluder


@functools.cache
def pool() -> ThreadPoolExecutor:
    return ThreadPoolExecutor(1, thread_name_prefix="test-raster")


@pytest.fixture(autouse=True, scope="module")
def split_any_window():
    """Windows split in two however small (the scene's are large; these rasters are quick)."""
    before = raster._SPLIT_MIN_PX
    raster._SPLIT_MIN_PX = 0
    yield
    raster._SPLIT_MIN_PX = before


def raster_args(name: str, rotation_deg, azimuth: float, elevation: float, side_px: int):
    posed = PosedOccluder.make(occluder(name), Pose(rotation_deg=rotation_deg), Sun(azimuth, elevation))
    ground = posed.ground_vertices()
    lo, hi = ground.min(0) - 0.2, ground.max(0) + 0.2
    pixel_m = float((hi - lo).max()) / side_px
    grid = GroundGrid(pixel_m, (float(lo[0]), float(hi[1])), int(np.ceil((hi[0] - lo[0]) / pixel_m)) + 1,
                      int(np.ceil((hi[1] - lo[1]) / pixel_m)) + 1)
    return grid, posed.world, posed.light, posed.silhouette, ground


def check_window(args, exact_px: float, threaded: bool) -> None:
    whole = rasterise_shadow(*args)
    near = rasterise_shadow(*args, exact_px=exact_px, pool=pool() if threaded else None)
    np.testing.assert_array_equal(near.hard, whole.hard)
    within = whole.boundary_dist_px <= exact_px
    np.testing.assert_array_equal(near.boundary_dist_px[within], whole.boundary_dist_px[within])
    np.testing.assert_array_equal(near.edge_label[within], whole.edge_label[within])
    assert np.all(near.boundary_dist_px[~within] > exact_px)


@settings(max_examples=25, deadline=None)
@given(name=st.sampled_from(["pillar", "ball", "dragon", "dragon-300"]),
       rotation=st.tuples(*[st.floats(-40.0, 40.0)] * 2, st.floats(0.0, 360.0)),
       azimuth=st.floats(0.0, 360.0), elevation=st.floats(15.0, 80.0), side_px=st.integers(60, 700),
       exact_px=st.floats(1.0, 80.0), threaded=st.booleans())
def test_distance_near_the_outline_is_the_whole_rasters(name, rotation, azimuth, elevation, side_px, exact_px,
                                                          threaded):
    check_window(raster_args(name, rotation, azimuth, elevation, side_px), exact_px, threaded)


def check_whole_raster(args) -> None:
    """The whole raster's distance and edge against OpenCV's transform from its seeds (the
    pixels at distance 0, numbered row-major as OpenCV numbers them)."""
    whole = rasterise_shadow(*args)
    seeds = whole.boundary_dist_px == 0
    assert seeds.any()
    dist, nearest = cv2.distanceTransformWithLabels(np.where(seeds, 0, 1).astype(np.uint8), cv2.DIST_L2,
                                                    cv2.DIST_MASK_5, labelType=cv2.DIST_LABEL_PIXEL)
    seed_edge = np.concatenate([[-1], whole.edge_label[seeds]]).astype(np.int32)
    np.testing.assert_array_equal(whole.boundary_dist_px, dist)
    np.testing.assert_array_equal(whole.edge_label, seed_edge[nearest])


@settings(max_examples=15, deadline=None)
@given(name=st.sampled_from(["pillar", "ball", "dragon", "dragon-300"]),
       rotation=st.tuples(*[st.floats(-40.0, 40.0)] * 2, st.floats(0.0, 360.0)),
       azimuth=st.floats(0.0, 360.0), elevation=st.floats(15.0, 80.0), side_px=st.integers(60, 700))
def test_whole_raster_is_opencvs_distance_transform(name, rotation, azimuth, elevation, side_px):
    check_whole_raster(raster_args(name, rotation, azimuth, elevation, side_px))


@pytest.mark.parametrize("exact_px", [0.5, 2.0, 1e4])
def test_window_extremes(exact_px):
    """A margin under a pixel; one larger than the raster (one window, all of it)."""
    check_window(raster_args("dragon", (10.0, -5.0, 30.0), 250.0, 35.0, 400), exact_px, True)


def test_a_half_without_seeds_is_far():
    """A shadow in the raster's top rows only: the lower half's window holds no seed."""
    args = raster_args("ball", (0.0, 0.0, 0.0), 180.0, 40.0, 300)
    grid = args[0]
    tall = GroundGrid(grid.pixel_m, grid.origin_m, grid.width, grid.height * 4)
    check_window((tall, *args[1:]), 5.0, True)
