"""The forward-only scene image (softshadow.scene_frame, docs/projector.md).

- ``plan_dense_points`` makes the same plan as ``plan_points``' light-space back end (every
  leaf equal), with and without normals, with the object's own faces given, on a receiver mesh,
  on one thread and on two over several blocks of points; its compiled candidate edges equal
  ``raster.candidate_labels``' (labels missing, at the raster's border, with and without
  outline neighbours).
- ``render_frame`` draws ``render_scene``'s image (same lights and band k) to rounding: the sun,
  a projector, a receiver mesh, the ground; no sun; a top-down map.
- ``FrameRenderer`` keeps its buffers between frames without mixing frames up (images equal to
  fresh ``render_frame`` calls, across a change of image size), and the background where a
  frame sees nothing.
- Back-face culling of a closed mesh changes no pixel of the z-buffer.
"""

from __future__ import annotations

import dataclasses
import functools

import jax
import numpy as np
import pytest

import softshadow as ss
from softshadow import (GroundGrid, Pose, Projector, SceneLights, SoftShadowModel, Sun, look_at_camera, render_frame,
                        render_scene, sine_slide)
from softshadow.internal import FRAME_STEPS, PointBlocks, Surface, plan_dense_points, visible_surfaces
from softshadow.scene_render import _object_surface


@functools.cache
def model_of(name: str) -> SoftShadowModel:
    return SoftShadowModel.from_mesh(name, footprint=False, hidden_sky=False)


def _step() -> Surface:
    """A receiver mesh: a 0.3 m step beside the object, open (not closed)."""
    import trimesh
    box = trimesh.creation.box((1.2, 3.0, 0.3))
    return Surface.from_trimesh(box, position=(1.6, 0.0, 0.15), albedo=(0.6, 0.7, 0.8), name="step")


def _plans_equal(a, b) -> None:
    for x, y in zip(jax.tree_util.tree_leaves(a), jax.tree_util.tree_leaves(b)):
        np.testing.assert_array_equal(np.asarray(x), np.asarray(y))


@pytest.mark.parametrize("mesh, sun, with_normals", [
    ("ball", (200.0, 40.0), True),
    ("pillar", (250.0, 35.0), True),
    ("pillar", (120.0, 60.0), False),
])
def test_dense_plan_equals_plan_points(mesh, sun, with_normals):
    model = model_of(mesh)
    pose = Pose(rotation_deg=(0.0, 0.0, 25.0))
    cam = look_at_camera((3.5, -4.0, 3.0), (0.0, 0.0, 0.5), 120, 90, 50.0)
    vis = visible_surfaces(cam, [_object_surface(model, pose, 0.8), _step()], 0.8)
    normals = vis.normals if with_normals else None
    sun = Sun(*sun)
    ref = model.plan_points(sun, pose, vis.points, 0.02, normals=normals, backend="light")
    dense = plan_dense_points(model.occluder, pose, sun, vis.points, 0.02, normals)
    assert dense.band.size > 20 and dense.hard.sum() > 50, "the scene must show a shadow and a penumbra"
    _plans_equal(ref, dense.point_plan())
    # The object's own faces given: a point whose face is the nearest to the sun skips the lookup.
    on_object = np.where(vis.surface.ravel()[vis.pixel] == 0, vis.face.ravel()[vis.pixel], -1)
    _plans_equal(ref, plan_dense_points(model.occluder, pose, sun, vis.points, 0.02, normals,
                                        faces=on_object).point_plan())
    # The runs of points out of reach skipped by their bounds: the same plan.
    blocks = PointBlocks.of(vis.points, normals)
    _plans_equal(ref, plan_dense_points(model.occluder, pose, sun, vis.points, 0.02, normals,
                                        blocks=blocks).point_plan())


def test_point_blocks_skip_runs_out_of_reach_for_the_same_plan():
    """A wide view of the ground (most runs of points far from the shadow, their normals one
    and the same) and the object: the bounds and uniform normals per run are NumPy's, the plan
    with them is the plan without, for suns all around, and blocks made for other points are
    refused."""
    from softshadow.dense_plan import RUN_POINTS, _depth_max_kernel
    model = model_of("pillar")
    cam = look_at_camera((9.0, -11.0, 7.0), (0.0, 0.0, 0.0), 320, 240, 60.0)
    vis = visible_surfaces(cam, [_object_surface(model, Pose(), 0.8)], 0.8)
    n = len(vis.points)
    blocks = PointBlocks.of(vis.points, vis.normals)
    pad = -n % RUN_POINTS
    runs = np.concatenate([vis.points, np.repeat(vis.points[-1:], pad, 0)]).reshape(-1, RUN_POINTS, 3)
    np.testing.assert_array_equal(blocks.lo, runs.min(1))
    np.testing.assert_array_equal(blocks.hi, runs.max(1))
    normal_runs = np.concatenate([vis.normals, np.repeat(vis.normals[-1:], pad, 0)]).reshape(-1, RUN_POINTS, 3)
    uniform = (normal_runs == normal_runs[:, :1]).all(axis=(1, 2))
    np.testing.assert_array_equal(blocks.uniform, uniform)
    assert 0.2 < uniform.mean() < 1.0, "the view must hold runs on the ground alone and runs on the object"
    # Every seventh normal tilted at random: no run is uniform, those out of reach test each point.
    tilted = vis.normals.copy()
    tilted[::7] += np.random.default_rng(3).normal(0.0, 0.8, tilted[::7].shape)
    tilted /= np.linalg.norm(tilted, axis=1, keepdims=True)
    assert not PointBlocks.of(vis.points, tilted).uniform.any()
    for azimuth, elevation in [(0.0, 20.0), (100.0, 45.0), (210.0, 70.0), (300.0, 30.0)]:
        sun = Sun(azimuth, elevation)
        for normals in (vis.normals, tilted, None):
            ref = plan_dense_points(model.occluder, Pose(), sun, vis.points, 0.03, normals)
            got = plan_dense_points(model.occluder, Pose(), sun, vis.points, 0.03, normals,
                                    blocks=PointBlocks.of(vis.points, normals))
            assert ref.band.size > 20
            _plans_equal(ref.point_plan(), got.point_plan())
        basis = np.stack([np.zeros(3), [1.0, 0, 0], [0, 1.0, 0], -np.asarray(sun.light_np)])
        assert _depth_max_kernel()(vis.points, basis, blocks.lo, blocks.hi) == \
            _depth_max_kernel()(vis.points, basis, np.zeros((0, 3)), np.zeros((0, 3)))
    with pytest.raises(ValueError, match="runs of points"):
        plan_dense_points(model.occluder, Pose(), Sun(0.0, 30.0), vis.points, 0.03, vis.normals,
                          blocks=PointBlocks.of(vis.points[:-RUN_POINTS]))


def test_dense_plan_on_one_and_two_threads_over_several_blocks():
    """The compiled passes gather points block by block (in parallel, then in order): with points in
    several blocks, on one thread and on two, the plan is ``plan_points``'."""
    import numba

    from softshadow.dense_plan import _BLOCK
    model = model_of("ball")
    cam = look_at_camera((3.0, -3.5, 2.5), (0.3, 0.0, 0.4), 200, 150, 55.0)
    vis = visible_surfaces(cam, [_object_surface(model, Pose(), 0.8), _step()], 0.8)
    sun = Sun(215.0, 38.0)
    ref = model.plan_points(sun, Pose(), vis.points, 0.02, normals=vis.normals, backend="light")
    before = numba.get_num_threads()
    try:
        for threads in (1, min(2, numba.config.NUMBA_NUM_THREADS)):
            numba.set_num_threads(threads)
            dense = plan_dense_points(model.occluder, Pose(), sun, vis.points, 0.02, vis.normals,
                                      scratch=ss.internal.Scratch())
            blocks = np.unique(dense.band // _BLOCK)
            assert len(blocks) >= 2 and len(vis.points) > 2 * _BLOCK, "the band must span several blocks"
            _plans_equal(ref, dense.point_plan())
    finally:
        numba.set_num_threads(before)


def test_dense_plan_block_passes_equal_their_one_pass_rules():
    """The test and band passes, parallel over blocks of points, against their rules in NumPy on
    random points over several blocks (the lists in order, the box over all of them)."""
    import numba

    from softshadow.dense_plan import _BLOCK, _band_kernel, _test_kernel
    rng = np.random.default_rng(11)
    m = 3 * _BLOCK + 123
    in_view = (rng.random(m) < 0.4).astype(np.uint8)
    att = rng.random(m) < 0.2
    d = rng.uniform(0.0, 2.0, m)
    uv = rng.normal(0.0, 1.0, (m, 2))
    want_test = np.flatnonzero((in_view > 0) & ~att & (d <= 1.5))
    label = rng.integers(-1, 20, m).astype(np.int32)
    dist = rng.uniform(0.0, 0.05, m).astype(np.float32)
    edge_depth, frac = rng.uniform(0.0, 1.0, 20), rng.choice([0.5, 1.0], 20)
    cand = rng.permutation(m + 50)[:m]
    per_m, fraction, margin, near_m = 0.04, 0.75, 0.005, 0.002
    width = per_m * np.maximum(d - edge_depth[np.maximum(label, 0)], 0.0)
    in_band = (label >= 0) & (dist <= fraction * width + margin) & ~att
    want_near = (dist <= 0.25 * width + near_m) & (frac[label] >= 0.99)
    before = numba.get_num_threads()
    try:
        for threads in (1, min(2, numba.config.NUMBA_NUM_THREADS)):
            numba.set_num_threads(threads)
            behind, test, box = np.ones(m, bool), np.empty(m, np.int64), np.empty(4)
            hard = np.full(m + 50, 7.0)
            n = _test_kernel()(cand, in_view, att, d, uv, 1.5, behind, hard, test, box)
            np.testing.assert_array_equal(test[:n], want_test)
            np.testing.assert_array_equal(behind, (in_view > 0) & ~att & (d > 1.5))
            np.testing.assert_array_equal(box, [*uv[want_test].min(0), *uv[want_test].max(0)])
            np.testing.assert_array_equal(hard[cand], (behind | att).astype(float))
            assert (hard[np.setdiff1d(np.arange(m + 50), cand)] == 7.0).all()
            band, near_b = np.empty(m, np.int64), np.empty(m, bool)
            n = _band_kernel()(d, label, dist, att, edge_depth, per_m, frac, True, fraction, margin, near_m, band,
                               near_b)
            np.testing.assert_array_equal(band[:n], np.flatnonzero(in_band))
            np.testing.assert_array_equal(near_b[:n], want_near[in_band])
    finally:
        numba.set_num_threads(before)
    assert len(np.unique(want_test // _BLOCK)) == 4 and 0 < want_near[in_band].sum() < in_band.sum()


@pytest.mark.parametrize("with_neighbours", [True, False])
def test_dense_plan_candidate_edges_equal_candidate_labels(with_neighbours):
    from softshadow.dense_plan import _CANDIDATE_OFFSETS, _candidates_kernel
    from softshadow.plan import CANDIDATE_RADII_PX, N_CANDIDATES
    from softshadow.raster import candidate_labels
    rng = np.random.default_rng(7)
    h, w, pixel_m, ox, oy = 40, 50, 0.1, -1.0, 2.0
    # Voronoi-like cells of labels (-1: none) so that neighbouring samples share and differ.
    cells = rng.integers(-1, 30, (h // 4 + 1, w // 4 + 1)).astype(np.int32)
    edge_label = np.ascontiguousarray(np.repeat(np.repeat(cells, 4, 0), 4, 1)[:h, :w])
    neighbours = rng.integers(-1, 30, (30, 2)) if with_neighbours else None
    # Points over the raster and beyond its border (clipped to it).
    uv = np.column_stack([rng.uniform(ox - 0.5, ox + w * pixel_m + 0.5, 400),
                          rng.uniform(oy - h * pixel_m - 0.5, oy + 0.5, 400)])
    sel = np.sort(rng.choice(400, 300, replace=False))
    cols = np.clip(np.rint((uv[sel, 0] - ox) / pixel_m).astype(np.int64), 0, w - 1)
    rows = np.clip(np.rint((oy - uv[sel, 1]) / pixel_m).astype(np.int64), 0, h - 1)
    want = np.maximum(candidate_labels(edge_label, rows, cols, radii=CANDIDATE_RADII_PX, max_candidates=N_CANDIDATES,
                                       neighbours=neighbours), 0)
    got = np.full((len(sel), N_CANDIDATES), -7, np.int32)
    _candidates_kernel()(uv, sel, ox, oy, pixel_m, edge_label,
                         np.full((0, 2), -1, np.int64) if neighbours is None else neighbours, _CANDIDATE_OFFSETS, got)
    assert (rows == 0).any() and (cols == w - 1).any() and (edge_label[rows, cols] < 0).any()
    assert len({tuple(r) for r in want}) > 50 and (want[:, 2] != want[:, 0]).any()
    np.testing.assert_array_equal(got, want)


def _scene(size=(120, 90)):
    cam = look_at_camera((3.0, -4.0, 2.6), (0.0, 0.0, 0.5), *size, 50.0)
    proj = Projector((-3.0, -2.5, 3.0), (0.0, 0.0, 0.5), sine_slide(6, 0.8, 64), fov_deg=45.0, shadow_px=256)
    return cam, proj


@pytest.mark.parametrize("mesh, with_sun, receiver", [("ball", True, True), ("pillar", True, False),
                                                      ("ball", False, True)])
def test_render_frame_equals_render_scene(mesh, with_sun, receiver):
    model = model_of(mesh)
    cam, proj = _scene()
    sun = Sun(230.0, 40.0) if with_sun else None
    lights = SceneLights(0.15, 0.9, 0.02)
    receivers = [_step()] if receiver else []
    args = (cam, model, Pose(), lights, sun, [proj])
    ref = render_scene(*args, receivers=receivers, object_albedo=0.85, ground_albedo=0.8, range_k_max=0.02)
    frame = render_frame(*args, receivers=receivers, object_albedo=0.85, ground_albedo=0.8)
    ref_image = np.asarray(ref.image)
    assert ref_image.max() > 0.5 and np.ptp(ref_image) > 0.3
    np.testing.assert_allclose(frame.image, ref_image, rtol=0, atol=1e-12)
    np.testing.assert_array_equal(frame.visible.surface, ref.setup.visible.surface)
    assert set(frame.milliseconds) <= set(FRAME_STEPS)


def test_render_frame_top_down_map():
    model = model_of("pillar")
    grid = GroundGrid.around((0.8, 0.8), 3.0, 64)
    _, proj = _scene()
    lights = SceneLights.from_rho(Sun(200.0, 45.0), 0.02, 0.3)
    ref = render_scene(grid, model, Pose(), lights, Sun(200.0, 45.0), [proj], range_k_max=0.02)
    frame = render_frame(grid, model, Pose(), lights, Sun(200.0, 45.0), [proj])
    np.testing.assert_allclose(frame.image, np.asarray(ref.image), rtol=0, atol=1e-12)


def test_frame_renderer_reuses_its_buffers_without_mixing_frames():
    model = model_of("ball")
    renderer = ss.FrameRenderer(threads=2)
    try:
        for size, azimuth, k in (((120, 90), 200.0, 0.01), ((120, 90), 240.0, 0.03), ((80, 60), 210.0, 0.02),
                                 ((120, 90), 200.0, 0.01)):
            cam, proj = _scene(size)
            args = (cam, model, Pose(), SceneLights(0.2, 0.8, k), Sun(azimuth, 40.0), [proj])
            got = renderer.render(*args, receivers=[_step()]).image.copy()
            np.testing.assert_array_equal(got, render_frame(*args, receivers=[_step()]).image)
    finally:
        renderer.close()


def test_frame_renderer_paints_the_background_where_a_frame_sees_nothing():
    """A view with sky pixels after one that sees something everywhere (the buffers hold its
    pixels): the sky is the background, the rest render_scene's image."""
    model = model_of("ball")
    lights = SceneLights(0.2, 0.8, 0.01)
    down = look_at_camera((3.0, -3.0, 3.0), (0.0, 0.0, 0.5), 64, 48, 40.0)
    horizon = look_at_camera((3.0, -3.0, 1.0), (-3.0, 3.0, 1.5), 64, 48, 60.0)
    renderer = ss.FrameRenderer(threads=1)
    try:
        first = renderer.render(down, model, Pose(), lights, Sun(200.0, 40.0), background=0.5)
        assert len(first.visible.pixel) == 64 * 48
        frame = renderer.render(horizon, model, Pose(), lights, Sun(200.0, 40.0), background=0.3)
        sky = frame.visible.surface == ss.internal.NOTHING
        assert sky.any() and (~sky).any()
        np.testing.assert_array_equal(frame.image[sky], 0.3)
        ref = render_scene(horizon, model, Pose(), lights, Sun(200.0, 40.0), background=0.3, range_k_max=0.01)
        np.testing.assert_allclose(frame.image, np.asarray(ref.image), rtol=0, atol=1e-12)
    finally:
        renderer.close()


def test_back_face_culling_changes_no_pixel():
    model = model_of("ball")
    surf = _object_surface(model, Pose(position=(0.2, 0.1, 0.0)), 0.8)
    assert surf.closed, "the ball is closed and outward-wound"
    cam = look_at_camera((2.0, -3.0, 2.0), (0.0, 0.0, 0.8), 96, 72, 50.0)
    open_surf = Surface(surf.vertices, surf.faces, surf.albedo, normals=surf.normals)
    for camera in (cam, GroundGrid.around((0.0, 0.0), 3.0, 64)):
        a, b = visible_surfaces(camera, [surf], 0.8), visible_surfaces(camera, [open_surf], 0.8)
        np.testing.assert_array_equal(a.face, b.face)
        np.testing.assert_array_equal(a.points, b.points)
    # A camera inside the near plane's reach of the mesh cuts it open: nothing is culled then.
    close = look_at_camera((0.0, 0.0, 1.0), (0.0, 1.0, 1.0), 64, 48, 90.0)
    np.testing.assert_array_equal(visible_surfaces(close, [surf], 0.8).face,
                                  visible_surfaces(close, [open_surf], 0.8).face)


def test_surface_normals_are_checked():
    with pytest.raises(ValueError, match="one normal per face"):
        Surface(np.eye(3), [[0, 1, 2]], normals=np.zeros((2, 3)))


def test_frame_renderer_remakes_what_changed():
    """The renderer keeps the posed object, the casters and the projectors' maps between frames
    while their inputs stay; a moved pose, projector or receiver (also one changed in place) is
    seen: every frame equals a fresh render_frame."""
    model = model_of("pillar")
    cam, proj = _scene()
    moved = Projector((-2.0, -3.5, 3.2), (0.0, 0.0, 0.5), proj.slide, fov_deg=45.0, shadow_px=256)
    for threads in (1, 2):
        step = _step()
        frames = [(Pose(), proj), (Pose(), proj), (Pose(position=(0.2, 0.0, 0.0)), proj),
                  (Pose(position=(0.2, 0.0, 0.0)), moved), (Pose(position=(0.2, 0.0, 0.0)), None)]
        renderer = ss.FrameRenderer(threads=threads)
        try:
            for i, (pose, projector) in enumerate(frames):
                if projector is None:  # the step raised in place: its shadow moves in the projector's map
                    projector = moved
                    step.vertices[:, 2] += 0.4
                args = (cam, model, pose, SceneLights(0.2, 0.8, 0.02), Sun(220.0, 40.0), [projector])
                got = renderer.render(*args, receivers=[step]).image.copy()
                np.testing.assert_array_equal(got, render_frame(*args, receivers=[step]).image, err_msg=f"frame {i}")
        finally:
            renderer.close()


def test_frame_renderer_keeps_what_each_pixel_sees_while_the_camera_stays():
    """While the camera, the surfaces and the ground stay, the renderer keeps what each pixel sees
    and the projector's light (only the sun or the projector moving); a moved camera, a receiver
    moved in place or the ground taken away is seen: every frame equals a fresh render_frame."""
    model = model_of("pillar")
    cam, proj = _scene()
    moved_cam = ss.PinholeCamera(cam.K, cam.R, cam.t + (0.05, 0.0, 0.0), cam.width, cam.height)  # moved sideways
    # Another slide from the same place (the same shadow map, another light), then another place.
    other_slide = Projector(proj.position, proj.target, sine_slide(3, 0.5, 64), fov_deg=45.0, shadow_px=256)
    moved_proj = Projector((-2.0, -3.5, 3.2), (0.0, 0.0, 0.5), proj.slide, fov_deg=45.0, shadow_px=256)
    step = _step()
    frames = [(cam, 220.0, proj, 0.8), (cam, 225.0, proj, 0.8), (cam, 225.0, other_slide, 0.8),
              (cam, 225.0, moved_proj, 0.8), (moved_cam, 225.0, moved_proj, 0.8), (cam, 230.0, moved_proj, 0.8),
              (cam, 230.0, moved_proj, None), (cam, 230.0, moved_proj, None)]
    for threads in (1, 2):
        renderer = ss.FrameRenderer(threads=threads)
        seen, lit = [], []
        try:
            for i, (camera, azimuth, projector, ground) in enumerate(frames):
                if i == 7:  # the step raised in place: what the camera sees changes
                    step.vertices[:, 2] += 0.3
                args = (camera, model, Pose(), SceneLights(0.2, 0.8, 0.02), Sun(azimuth, 40.0), [projector])
                frame = renderer.render(*args, receivers=[step], ground_albedo=ground)
                seen.append(frame.visible)
                lit.append(renderer.scratch._memo["frame.light"][1])
                np.testing.assert_array_equal(frame.image.copy(), render_frame(*args, receivers=[step],
                                                                               ground_albedo=ground).image,
                                              err_msg=f"frame {i}, {threads} thread(s)")
        finally:
            renderer.close()
        kept = [a is b for a, b in zip(seen[1:], seen[:-1])]
        assert kept == [True, True, True, False, False, False, False], kept
        assert [a is b for a, b in zip(lit[1:], lit[:-1])] == [True, False, False, False, False, False, False]


def test_scratch_memo_keeps_a_result_while_its_inputs_stay():
    scratch = ss.internal.Scratch()
    made = []

    def make():
        made.append(1)
        return len(made)

    a, key = np.arange(4.0), object()
    assert scratch.memo("x", (a, key, 1.5, "s"), make) == 1
    assert scratch.memo("x", (a.copy(), key, 1.5, "s"), make) == 1  # arrays by value
    a[0] = 9.0  # changed in place: seen
    assert scratch.memo("x", (a, key, 1.5, "s"), make) == 2
    assert scratch.memo("x", (a, object(), 1.5, "s"), make) == 3  # other objects by identity
    assert scratch.memo("x", (a.astype(np.float32), key, 1.5, "s"), make) == 4  # dtype counts
    assert scratch.memo("x", (a, key, 2.5, "s"), make) == 5
    assert scratch.memo("y", (a, key, 2.5, "s"), make) == 6  # per name


@pytest.mark.parametrize("dtype", [np.float64, np.float32])
def test_zbuffer_on_two_threads_equals_one(dtype):
    """Many faces are drawn in two halves on two threads and merged: the same buffer bit for bit
    (ties on shared edges keep the lower face, as one thread does)."""
    import numba
    import trimesh

    from softshadow.shadowmap import SPLIT_FACES, rasterise_depth
    sphere = trimesh.creation.icosphere(subdivisions=4)
    rng = np.random.default_rng(3)
    # Both windings, shuffled: every face drawn twice (ties), and each half holds winners.
    faces = rng.permutation(np.vstack([sphere.faces, sphere.faces[:, ::-1]]))
    assert len(faces) >= SPLIT_FACES
    xy = sphere.vertices[:, :2] * 30.0 + 40.0 + rng.normal(0, 0.01, (len(sphere.vertices), 2))
    depth = (sphere.vertices[:, 2] + 2.0).astype(dtype)
    before = numba.get_num_threads()
    try:
        numba.set_num_threads(1)
        one = rasterise_depth(xy, depth, faces, (80, 90))
        numba.set_num_threads(min(2, numba.config.NUMBA_NUM_THREADS))
        two = rasterise_depth(xy, depth, faces, (80, 90), threads=2, scratch=ss.internal.Scratch())
    finally:
        numba.set_num_threads(before)
    assert (one[1] >= 0).sum() > 2500 and (one[1] >= len(faces) // 2).sum() > 500, "both halves must win pixels"
    np.testing.assert_array_equal(one[0], two[0])
    np.testing.assert_array_equal(one[1], two[1])


@pytest.mark.parametrize("dtype", [np.float64, np.float32])
@pytest.mark.parametrize("height", [256, 257, 400])
def test_few_faces_on_two_threads_by_rows_equal_one(dtype, height):
    """Few faces on a large buffer are drawn by halves of the rows on two threads: the same
    buffer bit for bit, faces spanning the rows' split and ties on shared edges included."""
    import numba
    import trimesh

    from softshadow.shadowmap import SPLIT_FACES, SPLIT_ROWS_PX, rasterise_depth
    sphere = trimesh.creation.icosphere(subdivisions=2)  # 320 faces
    rng = np.random.default_rng(5)
    faces = rng.permutation(np.vstack([sphere.faces, sphere.faces[:, ::-1]]))
    assert len(faces) < SPLIT_FACES and height * 300 >= SPLIT_ROWS_PX
    xy = sphere.vertices[:, :2] * [140.0, 0.45 * height] + [150.0, height / 2] \
        + rng.normal(0, 0.01, (len(sphere.vertices), 2))
    depth = (sphere.vertices[:, 2] + 2.0).astype(dtype)
    before = numba.get_num_threads()
    try:
        numba.set_num_threads(1)
        one = rasterise_depth(xy, depth, faces, (height, 300))
        numba.set_num_threads(min(2, numba.config.NUMBA_NUM_THREADS))
        two = rasterise_depth(xy, depth, faces, (height, 300), threads=2)
    finally:
        numba.set_num_threads(before)
    split = height // 2
    assert (one[1][split - 1] >= 0).sum() > 100 and (one[1][split] >= 0).sum() > 100
    np.testing.assert_array_equal(one[0], two[0])
    np.testing.assert_array_equal(one[1], two[1])


@pytest.mark.parametrize("m, two_threads", [(1, False), (8, False), (9, False), (32, False), (33, False), (72, False),
                                           (75, False), (33, True), (72, True), (75, True), (75, "busy")])
def test_band_alpha_in_chunks_equals_one_evaluation(monkeypatch, m, two_threads):
    """The penumbra evaluated chunk by chunk (full chunks, then a small or a large padded one),
    on one thread or shared with a second (or with that thread busy throughout: this one
    evaluates them all), is the formula evaluated over the whole band at once, point for point."""
    import threading
    from concurrent.futures import ThreadPoolExecutor

    from softshadow import scene_frame
    from softshadow.evaluate import plan_alpha_jit
    model = model_of("ball")
    cam, _ = _scene()
    sun = Sun(230.0, 40.0)
    vis = visible_surfaces(cam, [_object_surface(model, Pose(), 0.8)], 0.8)
    plan = plan_dense_points(model.occluder, Pose(), sun, vis.points, 0.02, vis.normals)
    assert len(plan.band) >= 75
    whole = plan.band_plan()
    pts = np.zeros((len(whole.hard), 3))
    pts[:len(plan.band)] = vis.points[plan.band]
    ref = np.asarray(plan_alpha_jit(pts, whole, Pose(), sun, 0.02, model.rule, model.profile, None, model.corners))
    part = dataclasses.replace(plan, band=plan.band[:m], edge_id=plan.edge_id[:m], near_boundary=plan.near_boundary[:m])
    monkeypatch.setattr(scene_frame, "PENUMBRA_CHUNKS", (8, 32))
    pool = ThreadPoolExecutor(1, thread_name_prefix="second") if two_threads else None
    free = threading.Event()
    if two_threads == "busy":
        pool.submit(free.wait, 60.0)
    evaluated = []  # the threads that evaluated the chunks
    jitted = scene_frame.plan_alpha_jit
    monkeypatch.setattr(scene_frame, "plan_alpha_jit", lambda *a: evaluated.append(
        threading.current_thread().name.startswith("second")) or jitted(*a))
    try:
        got = scene_frame.band_alpha(part, vis.points, model, Pose(), sun, 0.02, scratch=ss.internal.Scratch(),
                                     pool=pool)
    finally:
        free.set()
        if pool is not None:
            pool.shutdown()
    # The second thread gets chunks of more than the smallest size only (m = 33: one chunk of
    # 32, which this thread takes first, and one of 8).
    assert any(evaluated) == (two_threads is True and m > 64), evaluated
    assert got.shape == (m,)
    np.testing.assert_allclose(got, ref[:m], rtol=0, atol=1e-12)


@pytest.mark.parametrize("threads", [1, 2])
def test_a_frame_compiles_no_penumbra_as_its_band_changes_size(monkeypatch, threads):
    """As the sun moves, the band's size and the silhouette's edges change: after the first
    frame no frame compiles the penumbra again (a compile stalls a frame for about a second),
    on one thread or with the chunks shared by two; the two give the same images."""
    from softshadow import scene_frame
    from softshadow.evaluate import plan_alpha_jit
    monkeypatch.setattr(scene_frame, "PENUMBRA_CHUNKS", (64, 256))
    model = model_of("ball")
    cam = look_at_camera((3.0, -4.0, 2.6), (0.0, 0.0, 0.5), 160, 120, 50.0)
    suns = [Sun(200, 40), Sun(215, 35), Sun(230, 30), Sun(245, 25), Sun(260, 20)]

    bands, edges, images, compiled = [], [], [], []
    renderer = ss.FrameRenderer(threads=threads)
    try:
        for sun in suns:
            frame = renderer.render(cam, model, Pose(), SceneLights(0.2, 0.8, 0.02), sun)
            bands.append(len(frame.plan.band))
            edges.append(frame.plan.edge_count)
            images.append(frame.image.copy())
            compiled.append(plan_alpha_jit._cache_size())
    finally:
        renderer.close()
    assert max(bands) > 1.25 * min(bands) and len(set(edges)) > 1, (bands, edges)
    assert sum(b > 256 for b in bands) >= 3, "the band must span several chunks"
    assert compiled[1:] == compiled[:1] * 4, compiled
    if threads == 2:  # the chunks shared by two threads: the images of one
        one = ss.FrameRenderer(threads=1)
        try:
            for sun, image in zip(suns, images):
                np.testing.assert_array_equal(image, one.render(cam, model, Pose(), SceneLights(0.2, 0.8, 0.02),
                                                                sun).image)
        finally:
            one.close()


def test_scratch_capacity_keeps_a_size_while_the_count_fits():
    scratch = ss.internal.Scratch()
    grow = lambda n: 2 * n  # noqa: E731
    assert scratch.capacity("e", 10, grow) == 20
    assert scratch.capacity("e", 5, grow) == 20
    assert scratch.capacity("e", 20, grow) == 20
    assert scratch.capacity("e", 21, grow) == 42
    assert scratch.capacity("f", 3, grow) == 6  # per name
    with pytest.raises(ValueError, match="less than"):
        scratch.capacity("g", 4, lambda n: n - 1)


def test_dense_plan_while_the_posed_occluder_is_made_on_another_thread():
    """The points projected into the sun's view while another thread poses the occluder: the
    same plan; a posed occluder under another sun, or none of its vertices, is refused."""
    from concurrent.futures import ThreadPoolExecutor

    from softshadow.posed import PosedOccluder, posed_vertices
    model = model_of("pillar")
    pose = Pose(rotation_deg=(0.0, 0.0, 25.0))
    cam, _ = _scene()
    vis = visible_surfaces(cam, [_object_surface(model, pose, 0.8)], 0.8)
    sun = Sun(250.0, 35.0)
    world, rotation = posed_vertices(model.occluder, pose)
    ref = plan_dense_points(model.occluder, pose, sun, vis.points, 0.02, vis.normals)
    with ThreadPoolExecutor(1) as pool:
        made = pool.submit(PosedOccluder.lit_by, model.occluder, world, rotation, sun.light_np)
        _plans_equal(ref.point_plan(), plan_dense_points(model.occluder, pose, sun, vis.points, 0.02, vis.normals,
                                                         posed=made, world=world).point_plan())
        other = pool.submit(PosedOccluder.lit_by, model.occluder, world, rotation, Sun(120.0, 35.0).light_np)
        with pytest.raises(ValueError, match="not the world vertices under this sun"):
            plan_dense_points(model.occluder, pose, sun, vis.points, 0.02, vis.normals, posed=other, world=world)
        with pytest.raises(ValueError, match="needs its world vertices"):
            plan_dense_points(model.occluder, pose, sun, vis.points, 0.02, vis.normals, posed=made)


def test_penumbra_chunks_shared_by_points():
    from softshadow.scene_frame import _shared
    assert _shared([(0, 4096), (4096, 4096), (8192, 1024)], 1024) == ([(0, 4096), (8192, 1024)], [(4096, 4096)])
    assert _shared([(0, 1024)], 1024) == ([(0, 1024)], [])
    assert _shared([(0, 8192), (8192, 1024)], 1024) == ([(0, 8192), (8192, 1024)], [])  # the small one stays
    assert _shared([(0, 8192), (8192, 4096)], 1024) == ([(0, 8192)], [(8192, 4096)])
    assert _shared([(0, 8), (8, 8), (16, 8), (24, 8), (32, 32)], 4) == ([(0, 8), (16, 8), (32, 32)], [(8, 8), (24, 8)])
    assert _shared([(0, 8), (8, 8), (16, 8), (24, 8), (32, 32)], 8) == ([(0, 8), (8, 8), (16, 8), (24, 8)], [(32, 32)])


def test_dense_plan_tells_which_points_the_shadow_can_reach():
    """``reached``: every point outside the shadow's reach has its final hard shadow when it is
    called (another thread shades them then), the points within it are the band's superset."""
    model = model_of("ball")
    cam = look_at_camera((3.0, -3.5, 2.5), (0.3, 0.0, 0.4), 120, 90, 55.0)
    vis = visible_surfaces(cam, [_object_surface(model, Pose(), 0.8), _step()], 0.8)
    sun = Sun(215.0, 38.0)
    seen = []

    def reached(cand, hard):
        out = np.setdiff1d(np.arange(len(hard)), cand)
        seen.append((cand.copy(), out, hard[out].copy()))

    plan = plan_dense_points(model.occluder, Pose(), sun, vis.points, 0.02, vis.normals,
                             scratch=ss.internal.Scratch(), reached=reached)
    (cand, out, hard_out), = seen
    assert 0 < len(cand) < len(vis.points) and np.all(np.diff(cand) > 0)
    assert np.isin(plan.band, cand).all() and plan.hard[cand].sum() > 20 and (1 - plan.hard[out]).sum() > 20
    np.testing.assert_array_equal(plan.hard[out], hard_out)
    _plans_equal(plan_dense_points(model.occluder, Pose(), sun, vis.points, 0.02, vis.normals).point_plan(),
                 plan.point_plan())


def test_shading_in_two_parts_is_the_shading_in_one():
    """The points not listed (shaded while the plan is made, the background first), then the
    listed ones: the image of one shading pass."""
    from softshadow.scene_frame import _shade, _shade_listed, _shade_others
    rng = np.random.default_rng(5)
    n, h_w = 9000, 9500
    pixel = rng.permutation(h_w)[:n]
    normals = rng.normal(size=(n, 3))
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    shading = (pixel, normals, rng.integers(-1, 2, n), rng.uniform(0.2, 0.9, (3, 3)), 0.2, 0.8,
               np.array([0.3, -0.2, 0.93]), rng.integers(0, 2, n).astype(np.float64))
    light = rng.uniform(0, 0.5, (n, 3))
    listed = np.sort(rng.choice(n, 3000, replace=False))
    want = np.full((h_w, 3), np.nan)
    _shade(shading, light, 0.25, want, np.zeros(0, np.int64), np.zeros(0))
    got = np.full((h_w, 3), np.nan)
    _shade_others(shading, light, 0.25, got, listed)
    others = np.delete(np.arange(h_w), pixel[listed])
    np.testing.assert_array_equal(got[pixel[listed]], 0.25)  # the background so far
    np.testing.assert_array_equal(got[others], want[others])
    _shade_listed(shading, light, got, listed)
    np.testing.assert_array_equal(got, want)


def test_flat_runs_shade_as_every_point():
    """Runs with one normal, one surface and consecutive pixels (``_seen``'s flat runs: their
    normal, surface and pixel read once) shade exactly as point by point; a run that breaks any
    of the three is not flat."""
    from softshadow.dense_plan import RUN_POINTS
    from softshadow.scene_frame import _flat_runs_kernel, _shade, _shade_listed, _shade_others
    rng = np.random.default_rng(11)
    runs = 40
    n = runs * RUN_POINTS + 17  # a short last run
    pixel = np.arange(n) + 5
    normals = np.tile([0.0, 0.0, 1.0], (n, 1))
    surface = np.full(n, -1)
    breaks = {"normal": 3, "surface": 7, "pixel": 12}
    normals[breaks["normal"] * RUN_POINTS + 9] = [0.0, 0.6, 0.8]
    surface[breaks["surface"] * RUN_POINTS + 30] = 0
    pixel[breaks["pixel"] * RUN_POINTS + 40:] += 3  # a gap inside that run
    mixed = slice(20 * RUN_POINTS, 24 * RUN_POINTS)  # an object's points: normals of their own
    normals[mixed] = rng.normal(size=(4 * RUN_POINTS, 3))
    normals[mixed] /= np.linalg.norm(normals[mixed], axis=1, keepdims=True)
    surface[mixed] = 0
    flat = ss.internal.PointBlocks.of(rng.normal(size=(n, 3)), normals).uniform.copy()
    _flat_runs_kernel()(pixel, surface, flat)
    assert not flat[[*breaks.values(), 20, 21, 22, 23]].any() and flat.sum() == runs + 1 - 7
    h_w = int(pixel[-1]) + 4
    shading = (pixel, normals, surface, rng.uniform(0.2, 0.9, (2, 3)), 0.2, 0.8, np.array([0.3, -0.2, 0.93]),
               rng.integers(0, 2, n).astype(np.float64))
    light = rng.uniform(0, 0.5, (n, 3))
    band = np.sort(rng.choice(n, 200, replace=False))
    alpha = rng.uniform(0, 1, 200)
    want = np.full((h_w, 3), np.nan)
    _shade(shading, light, 0.25, want, band, alpha)
    got = np.full((h_w, 3), np.nan)
    _shade(shading, light, 0.25, got, band, alpha, flat)
    np.testing.assert_array_equal(got, want)
    listed = np.sort(rng.choice(n, 900, replace=False))
    want = np.full((h_w, 3), np.nan)
    _shade(shading, light, 0.25, want, np.zeros(0, np.int64), np.zeros(0))
    got = np.full((h_w, 3), np.nan)
    _shade_others(shading, light, 0.25, got, listed, flat)
    _shade_listed(shading, light, got, listed, flat)
    np.testing.assert_array_equal(got, want)


@pytest.mark.parametrize("busy", [False, True])
def test_dense_plan_shares_its_work_with_a_second_thread(monkeypatch, busy):
    """With a second thread packing the edges and making the band while this one tests the
    points near the outline, the plan is ``plan_points``'; with that thread busy throughout,
    this one makes the band."""
    import threading
    from concurrent.futures import ThreadPoolExecutor

    from softshadow import dense_plan
    model = model_of("pillar")
    pose = Pose(rotation_deg=(0.0, 0.0, 25.0))
    cam = look_at_camera((3.5, -4.0, 3.0), (0.0, 0.0, 0.5), 120, 90, 50.0)
    vis = visible_surfaces(cam, [_object_surface(model, pose, 0.8), _step()], 0.8)
    sun = Sun(250.0, 35.0)
    ref = model.plan_points(sun, pose, vis.points, 0.02, normals=vis.normals, backend="light")
    banded = []
    band_plan = dense_plan._band_plan
    monkeypatch.setattr(dense_plan, "_band_plan", lambda *a: banded.append(threading.current_thread().name)
                        or band_plan(*a))
    tested = []
    hard_shadow_at = ss.internal.PosedOccluder.hard_shadow_at
    monkeypatch.setattr(ss.internal.PosedOccluder, "hard_shadow_at", lambda self, uv, **kw: tested.append(
        (len(uv), threading.current_thread().name)) or hard_shadow_at(self, uv, **kw))
    free = threading.Event()
    with ThreadPoolExecutor(1, thread_name_prefix="second") as pool:
        if busy:
            pool.submit(free.wait, 60.0)
        try:
            dense = plan_dense_points(model.occluder, pose, sun, vis.points, 0.02, vis.normals, pool=pool,
                                      scratch=ss.internal.Scratch())
        finally:
            free.set()
    # Made once; by this thread when the second is busy (when it is free, by whichever gets to it
    # first: this one makes it when the second has not started it by then).
    assert len(banded) == 1 and not (busy and banded[0].startswith("second")), banded
    # The points near the outline, all tested at once on this thread.
    assert len(tested) == 1 and tested[0][0] >= 4 and not tested[0][1].startswith("second"), tested
    _plans_equal(ref, dense.point_plan())
