"""``softshadow bench``: renderer speed (and the fitter's speed and error) as JSON.

Render figures: a top-down ground map of each built-in mesh at 256, 512 and
1024 pixels, k = 0.01, rho = 0.3, sun azimuth 200 deg, elevation 40 deg.
``forward_ms`` is the whole render (the NumPy/OpenCV plan plus the JAX
evaluation); ``plan_ms`` the plan alone; ``forward_cached_ms`` reuses the plan
(as a fit does while the discrete choices hold); ``grad_ms`` is value and
gradient of a scalar loss of the image with respect to k, rho and the sun
angles, plan included, and ``grad_cached_ms`` without the plan. Times are
medians after compilation, in JAX's default float dtype (float32 unless x64 is
enabled; the result says which).
"""

from __future__ import annotations

import resource
import statistics
import time

__all__ = ["bench_render"]


def _median_ms(fn, repeats: int) -> float:
    fn()  # compile / warm up
    times = []
    for _ in range(repeats):
        t = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t)
    return 1000.0 * statistics.median(times)


def bench_render(sizes=(256, 512, 1024), meshes=("pillar", "ball", "dragon"), repeats: int = 7) -> dict:
    import jax
    import jax.numpy as jnp
    import numpy as np

    from softshadow import GroundGrid, Pose, ShadowParams, SoftShadowModel, Sun
    from softshadow.internal import project_to_ground

    out = {}
    sun, pose = Sun(200.0, 40.0), Pose()
    params = ShadowParams(0.01, 0.3)
    for name in meshes:
        model = SoftShadowModel.from_mesh(name)
        world = np.asarray(model.occluder.vertices)
        g = project_to_ground(world, sun.light_np)
        pts = np.vstack([g, world[:, :2]])
        centre = (pts.min(0) + pts.max(0)) / 2
        extent = float((pts.max(0) - pts.min(0)).max()) * 1.1
        out[name] = {"faces": int(model.occluder.n_faces)}
        for size in sizes:
            grid = GroundGrid.around(centre, extent, size)
            plan = model.plan_grid(sun, pose, grid, 0.01)

            def forward():
                model.ground_map(params, sun, pose, grid).block_until_ready()

            def forward_cached():
                model.ground_map(params, sun, pose, grid, plan=plan).block_until_ready()

            weights = jnp.asarray(np.random.default_rng(0).random((size, size)))

            def loss(p, s, pl):
                return jnp.sum(weights * model.ground_map(p, s, pose, grid, plan=pl))

            grad_fn = jax.value_and_grad(loss, argnums=(0, 1))

            def grad():
                pl = model.plan_grid(sun, pose, grid, 0.01)
                jax.block_until_ready(grad_fn(params, sun, pl))

            def grad_cached():
                jax.block_until_ready(grad_fn(params, sun, plan))

            def plan_only():
                model.plan_grid(sun, pose, grid, 0.01)

            out[name][str(size)] = {
                "forward_ms": round(_median_ms(forward, repeats), 2),
                "plan_ms": round(_median_ms(plan_only, repeats), 2),
                "forward_cached_ms": round(_median_ms(forward_cached, repeats), 2),
                "grad_ms": round(_median_ms(grad, repeats), 2),
                "grad_cached_ms": round(_median_ms(grad_cached, repeats), 2),
                "band_pixels": int(plan.n_band),
                "silhouette_edges": int(plan.n_edges),
                "outline_edges": int(np.count_nonzero(plan.raster.edge_outline_fraction > 0))
                if plan.raster is not None else 0,
            }
    out["peak_memory_mb"] = round(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0, 1)
    return out


def depth_receiver_scene(size: int = 512, mesh: str = "dragon"):
    """A range image of the built-in mesh standing on the ground in front of a 0.15 m step.

    A camera (``size`` x ``size`` pixels) looks at the scene; each pixel's ray is cast
    against the ground, the step and the mesh itself (trimesh), its distance along the
    optical axis kept as a range image (docs/formats.md: z_cam, metres), and the receiver
    points are unprojected from that range image. Returns (model, points (N, 3),
    normals (N, 3), camera); pixels that see nothing are left out.
    """
    import numpy as np
    import trimesh

    from softshadow import SoftShadowModel, look_at_camera

    model = SoftShadowModel.from_mesh(mesh)
    occ = model.occluder
    obj = trimesh.Trimesh(occ.vertices, occ.faces, process=False)
    ground = trimesh.Trimesh([[-6, -6, 0], [6, -6, 0], [6, 1.2, 0], [-6, 1.2, 0]], [[0, 1, 2], [0, 2, 3]])
    step = trimesh.creation.box(extents=(12.0, 6.0, 0.15))
    step.apply_translation((0.0, 1.2 + 3.0, 0.075))
    scene = trimesh.util.concatenate([obj, ground, step])
    camera = look_at_camera((2.2, -2.6, 2.4), (0.2, 0.9, 0.2), size, size, 60.0)
    rows, cols = np.mgrid[0:size, 0:size]
    dirs = camera.pixel_rays(cols.ravel(), rows.ravel())
    dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
    origins = np.broadcast_to(camera.centre, dirs.shape)
    loc, ray, tri = scene.ray.intersects_location(origins, dirs, multiple_hits=False)
    z_cam = np.full(size * size, np.nan)
    z_cam[ray] = (loc - camera.centre) @ camera.R[2]
    normals = np.zeros((size * size, 3))
    normals[ray] = scene.face_normals[tri]
    # The range image back to points, as a depth receiver reads it.
    ok = np.isfinite(z_cam)
    rays = camera.pixel_rays(cols.ravel()[ok], rows.ravel()[ok])
    points = camera.centre + rays * (z_cam[ok] / (rays @ camera.R[2]))[:, None]
    return model, points, normals[ok], camera


def bench_depth_receiver(size: int = 512, mesh: str = "dragon", repeats: int = 7) -> dict:
    """The light-space back end on a ``size``^2 range image (the mesh, the ground and a step)
    beside the ground back end on a ``size``^2 top-down map, in the same run.

    ``light_ms``: plan plus evaluation at every range-image point (``at_points`` with
    normals); ``ground_ms``: ``ground_map`` on a map framing the shadow (medians, the two
    calls alternating); ``ratio`` = light_ms / ground_ms; ``ratio_of_pairs``: the median of
    each light call's time over the ground call's after it; ``*_cpu_ms`` and ``cpu_ratio``: the
    same in the process's CPU time (all its threads), less moved by other jobs on a shared
    machine than the wall time.
    """
    import numpy as np

    from softshadow import GroundGrid, Pose, ShadowParams, Sun
    from softshadow.internal import project_to_ground

    model, points, normals, _ = depth_receiver_scene(size, mesh)
    sun, pose = Sun(200.0, 40.0), Pose()
    params = ShadowParams(0.01, 0.3)
    world = np.asarray(model.occluder.vertices)
    g = project_to_ground(world, sun.light_np)
    pts = np.vstack([g, world[:, :2]])
    grid = GroundGrid.around((pts.min(0) + pts.max(0)) / 2, float((pts.max(0) - pts.min(0)).max()) * 1.1, size)

    def light():
        model.at_points(params, sun, pose, points, normals).block_until_ready()

    def ground():
        model.ground_map(params, sun, pose, grid).block_until_ready()

    plan = model.plan_points(sun, pose, points, 0.01, normals)
    # Interleaved, so that both see the same load on a shared machine (one after the other, a
    # change of load between the two batches moved the ratio by half).
    light(), ground()  # compile / warm up
    times = {"light": [], "ground": []}
    cpu = {"light": [], "ground": []}
    for _ in range(repeats):
        for name, fn in (("light", light), ("ground", ground)):
            t, c = time.perf_counter(), time.process_time()
            fn()
            times[name].append(time.perf_counter() - t)
            cpu[name].append(time.process_time() - c)
    light_ms, ground_ms = (1000.0 * statistics.median(times[k]) for k in ("light", "ground"))
    light_cpu, ground_cpu = (1000.0 * statistics.median(cpu[k]) for k in ("light", "ground"))
    pair = statistics.median(a / b for a, b in zip(times["light"], times["ground"]))
    n = len(points)
    return {"points": int(n), "band_points": int(plan.active[:n].sum()),
            "hard_points": int(plan.hard[:n].sum()), "light_ms": round(light_ms, 2),
            "ground_ms": round(ground_ms, 2), "ratio": round(light_ms / ground_ms, 3),
            "ratio_of_pairs": round(pair, 3), "light_cpu_ms": round(light_cpu, 2),
            "ground_cpu_ms": round(ground_cpu, 2), "cpu_ratio": round(light_cpu / ground_cpu, 3),
            "repeats": repeats}
