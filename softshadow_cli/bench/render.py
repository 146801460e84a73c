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

    from softshadow import GroundGrid, Pose, ShadowParams, SoftShadowModel, Sun, project_to_ground

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
