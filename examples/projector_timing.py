"""Time the scene renderer's steps on the dragon (examples/projector/scene.toml's lights); prints JSON.

    python examples/projector_timing.py [--size 640x480] [--repeats 5]

Steps: the camera's z-buffer (``visible_surfaces``), each projector's perspective shadow map
and its light at the visible points, the sun's plan, and the JAX shading after compilation;
medians of ``repeats`` runs, milliseconds.
"""

from __future__ import annotations

import argparse
import json
import platform
import time
from pathlib import Path

import numpy as np

import softshadow as ss
from scene import load_scene


def _median_ms(fn, repeats: int):
    times, out = [], None
    for _ in range(repeats):
        t = time.perf_counter()
        out = fn()
        times.append(1e3 * (time.perf_counter() - t))
    return float(np.median(times)), out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--size", default="640x480")
    ap.add_argument("--repeats", type=int, default=5)
    args = ap.parse_args()
    w, h = (int(v) for v in args.size.split("x"))
    spec = load_scene(Path(__file__).parent / "projector" / "scene.toml")
    projectors = [p.projector(spec.base_dir) for p in spec.projectors]
    model = ss.SoftShadowModel.from_mesh(spec.object.mesh)
    pose, sun = ss.Pose(), ss.Sun(200.0, 40.0)
    camera = ss.look_at_camera((3.0, -4.0, 2.6), (0.0, 0.0, 0.5), w, h, 50.0)
    world, _ = ss.internal.posed_vertices(model.occluder, pose)
    surf = ss.internal.Surface(world, model.occluder.faces)
    out = {"mesh_faces": int(len(model.occluder.faces)), "size": args.size, "machine": platform.machine(),
           "repeats": args.repeats}
    out["visibility_ms"], vis = _median_ms(lambda: ss.internal.visible_surfaces(camera, [surf], 0.85), args.repeats)
    out["visible_points"] = int(len(vis.pixel))
    for i, proj in enumerate(projectors):
        out[f"projector{i}_shadow_map_ms"], smap = _median_ms(
            lambda: ss.internal.projector_shadow_map(proj, surf.vertices, surf.faces), args.repeats)
        out[f"projector{i}_light_ms"], _ = _median_ms(lambda: proj.irradiance(vis.points, vis.normals, smap),
                                                      args.repeats)
    out["sun_plan_ms"], _ = _median_ms(lambda: model.plan_points(sun, pose, vis.points, 0.03, normals=vis.normals),
                                       args.repeats)
    lights = ss.SceneLights.from_rho(sun, 0.02, 0.3)
    setup = ss.prepare_scene(camera, model, pose, sun, projectors, range_k_max=0.03)
    np.asarray(ss.shade_scene(setup, model, lights, sun, pose))  # compile
    out["shade_ms"], _ = _median_ms(lambda: np.asarray(ss.shade_scene(setup, model, lights, sun, pose)), args.repeats)
    out["render_scene_ms"], _ = _median_ms(
        lambda: np.asarray(ss.render_scene(camera, model, pose, lights, sun, projectors, range_k_max=0.03).image),
        args.repeats)
    print(json.dumps(out, indent=1))


if __name__ == "__main__":
    with ss.one_blas_thread():  # as the command line runs: (N, 3) @ (3, 3) is slow on many BLAS threads
        main()
