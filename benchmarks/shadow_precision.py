"""``softshadow bench --what precision``: the shadow map's depth in float32 against float64 (JSON).

The Dowling paper's concern: a shadow map's depth test in limited precision
makes a lit surface shadow itself (acne) or, with a large bias, detaches
shadows (peter-panning). Measured here on the depth-receiver scene of
``bench_depth_receiver`` (the dragon on the ground before a step, seen by a
512 x 512 camera, plus points sampled on the dragon itself), at the origin and
moved 100 m and 1 km away (float32 rounds world coordinates to ~8 um and
~60 um there):

- ``depth_error_m``: the occluder depth at the receiver points (the face plane
  at the point), float32 minus float64, median / 99th percentile / max;
- ``receiver_depth_error_m``: the same for the receiver points' own depth;
- ``lookups``, ``depth_error_over_bias``: points looked up in the map, and how many of them
  have a float32 occluder-depth error above ``bias_m``;
- ``hard_flips``: receiver points whose hard-shadow decision differs;
- ``alpha_rms``, ``alpha_max``: alpha, float32 plan and evaluation against float64;
- ``bias_m``: the float32 bias of an exact lookup at that map's pixel (BIAS_PX pixels plus
  16 ulps of the coordinates' magnitude), for comparison.
"""

from __future__ import annotations

__all__ = ["bench_shadow_precision"]


def _depths(model, pose, sun, points, dtype):
    """(occluder depth at the points, the points' depth, the map's pixel) in ``dtype``."""
    import numpy as np

    from softshadow import GroundGrid
    from softshadow.internal import LightFrame, PosedOccluder, shadow_map
    posed = PosedOccluder.make(model.occluder, pose, sun)
    world = posed.world
    # The frame's origin is the occluder's centre, as in the plan; its own rounding in float32
    # is part of what is measured.
    frame = LightFrame.of_light(posed.light, 0.5 * (world.min(0) + world.max(0)))
    uv_v, d_v = frame.project(world, dtype)
    uv_p, d_p = frame.project(points, dtype)
    lo, hi = uv_v.min(0).astype(np.float64), uv_v.max(0).astype(np.float64)
    pixel_m = float((hi - lo).max()) / 512
    grid = GroundGrid(pixel_m, (float(lo[0]), float(hi[1])), int((hi[0] - lo[0]) / pixel_m) + 2,
                      int((hi[1] - lo[1]) / pixel_m) + 2)
    faces = model.occluder.faces[posed.silhouette.lit]
    smap = shadow_map(grid, uv_v, d_v, faces, dtype)
    occ_depth, _, exact = smap.occluder_depth(uv_p)
    return occ_depth, d_p, exact, pixel_m


def bench_shadow_precision(size: int = 512, offsets_m=(0.0, 100.0, 1000.0)) -> dict:
    import jax
    import numpy as np
    import trimesh

    from softshadow import Pose, ShadowParams, Sun
    from softshadow.internal import depth_bias

    from .render import depth_receiver_scene

    model, points, normals, _ = depth_receiver_scene(size)
    obj = trimesh.Trimesh(model.occluder.vertices, model.occluder.faces, process=False)
    on_obj, face = trimesh.sample.sample_surface_even(obj, 20000, seed=0)
    points = np.vstack([points, on_obj])
    normals = np.vstack([normals, obj.face_normals[face]])
    sun = Sun(200.0, 40.0)
    params = ShadowParams(0.01, 0.3)
    out = {"points": int(len(points)), "object_points": int(len(on_obj))}
    for offset in offsets_m:
        shift = np.array([offset, offset, 0.0])
        pose = Pose(tuple(shift))
        pts = points + shift
        d64, p64, exact, pixel_m = _depths(model, pose, sun, pts, np.float64)
        d32, p32, _, _ = _depths(model, pose, sun, pts.astype(np.float32), np.float32)
        both = np.isfinite(d64) & np.isfinite(d32) & exact
        err = np.abs(d32[both].astype(np.float64) - d64[both])  # only where both depths exist
        perr = np.abs(p32.astype(np.float64) - p64)
        plan64 = model.plan_points(sun, pose, pts, 0.01, normals)
        plan32 = model.plan_points(sun, pose, pts, 0.01, normals, dtype=np.float32)
        n = len(pts)
        with jax.enable_x64(True):
            a64 = np.asarray(model.at_points(params, sun, pose, pts, normals, plan=plan64))
        with jax.enable_x64(False):
            a32 = np.asarray(model.at_points(ShadowParams(np.float32(0.01), np.float32(0.3)), sun, pose,
                                             pts.astype(np.float32), normals, plan=plan32))
        alpha = lambda s: (1.0 - s.astype(np.float64)) / 0.7
        q = lambda x: [float(f"{v:.3g}") for v in (np.median(x), np.percentile(x, 99), x.max())]
        bias = float(depth_bias(pixel_m, 0.0, 0.0, float(np.abs(pts).max()), np.float32))
        out[f"offset_{offset:g}_m"] = {
            "lookups": int(both.sum()), "depth_error_over_bias": int(np.count_nonzero(err > bias)),
            "depth_error_m": q(err), "receiver_depth_error_m": q(perr),
            "hard_flips": int(np.count_nonzero(plan64.hard[:n] != plan32.hard[:n])),
            "alpha_rms": float(f"{np.sqrt(np.mean((alpha(a32) - alpha(a64)) ** 2)):.3g}"),
            "alpha_max": float(f"{np.abs(alpha(a32) - alpha(a64)).max():.3g}"),
            "bias_m": float(f"{bias:.3g}"),
            "map_pixel_m": float(f"{pixel_m:.3g}")}
    out["legend"] = "error triples: median, 99th percentile, max (metres)"
    return out
