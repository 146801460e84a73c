"""Scaling: time and peak memory against faces and pixels for this renderer, the naive
renderer (every pixel against every edge) and the paper's algorithm, with log-log slopes.

Faces: the pillar (176), the ball (1,472), the real dragon decimated (5,000), as vendored
(26,584), and subdivided once (106,336) and twice then decimated (200,000). Pixels: the
pillar and the dragon at several map sizes. The naive renderer is left out where its
pixels x edges table would exceed ``naive_limit`` pairs (it is then marked skipped).
"""

from __future__ import annotations

import numpy as np

from .measure import timed

__all__ = ["scaling_meshes", "loglog_slope", "cost_model", "bench_scaling"]


def loglog_slope(x, y) -> float | None:
    """Slope of log(y) against log(x) (least squares); None with fewer than two points."""
    x, y = np.asarray(x, float), np.asarray(y, float)
    ok = (x > 0) & (y > 0)
    if ok.sum() < 2:
        return None
    return float(np.polyfit(np.log(x[ok]), np.log(y[ok]), 1)[0])


def scaling_meshes(face_counts):
    """{faces: trimesh} built from the bench meshes (decimated or subdivided dragon)."""
    import trimesh
    from .meshes import bench_mesh, decimated
    dragon = bench_mesh("dragon")
    out = {}
    for n in face_counts:
        if n == 176:
            out[n] = bench_mesh("pillar")
        elif n == 1472:
            out[n] = bench_mesh("ball")
        elif n <= len(dragon.faces):
            out[n] = decimated(dragon, n)
        else:
            v, f = np.asarray(dragon.vertices), np.asarray(dragon.faces)
            while len(f) < n:
                v, f = trimesh.remesh.subdivide(v, f)
            out[n] = decimated(trimesh.Trimesh(v, f, process=False), n)
    return out


def _row(name, mesh, grid, sun, light_rho, k, repeats, naive_limit):
    from softshadow import Pose, ShadowParams, SoftShadowModel
    from .naive import NaiveRenderer
    from .shoji import ShojiRenderer
    s_dir = -np.asarray(sun.light_np)
    model = SoftShadowModel.from_mesh(mesh)
    params = ShadowParams(k, light_rho)
    row = {"case": name, "faces": int(len(mesh.faces)), "pixels": grid.width * grid.height}
    ours = lambda: model.ground_map(params, sun, Pose(), grid).block_until_ready()
    row["softshadow"] = timed(ours, repeats)
    paper = ShojiRenderer(mesh)
    row["paper"] = timed(lambda: paper.render(s_dir, grid, 10.0, light_rho, 0.0), repeats)
    naive = NaiveRenderer(mesh)
    edges = naive.silhouette_edges(s_dir)
    row["silhouette_edges"] = edges
    if grid.width * grid.height * edges <= naive_limit:
        kept = []  # its render takes seconds: the memory run's image is the one compared

        def naive_run():
            kept[:] = [naive.render(s_dir, grid, k, light_rho)]

        row["naive"] = timed(naive_run, max(1, repeats // 2), warmup=0)
        a = np.asarray(ours())
        row["naive_vs_softshadow_rms"] = float(np.sqrt(np.mean((kept[0] - a) ** 2)))
    else:
        row["naive"] = {"skipped": f"{grid.width * grid.height * edges:.2e} pixel-edge pairs"}
    return row


def cost_model(rows: list[dict], renderer: str = "softshadow") -> dict:
    """Time against pixels plus silhouette edges, measured: ``renderer``'s median ms over the rows
    (by faces and by pixels) fitted, non-negative least squares, as t = a + b P + c E (P pixels,
    E silhouette edges) and, for contrast, as t = a + d P E (the naive renderer's law). Returns
    the coefficients and each law's RMS relative residual (the better law has the smaller)."""
    from scipy.optimize import nnls
    pts = [(r["pixels"], r["silhouette_edges"], r[renderer]["median_ms"]) for r in rows
           if "median_ms" in r[renderer]]
    if len(pts) < 4:
        return {"renderer": renderer, "points": len(pts)}
    p, e, t = (np.array(c, float) for c in zip(*pts))

    def law(columns):
        a = np.stack(columns, axis=1) / t[:, None]  # relative residuals: every row weighs the same
        coef, _ = nnls(a, np.ones_like(t))
        rel = a @ coef - 1.0
        return coef, float(np.sqrt(np.mean(rel ** 2))), float(np.max(np.abs(rel)))

    (a, b, c), rms_sum, max_sum = law([np.ones_like(t), p, e])
    (a2, d), rms_prod, max_prod = law([np.ones_like(t), p * e])
    return {"renderer": renderer, "points": len(pts),
            "pixels_plus_edges": {"ms": a, "ms_per_megapixel": 1e6 * b, "ms_per_thousand_edges": 1e3 * c,
                                  "rms_rel_residual": rms_sum, "max_rel_residual": max_sum},
            "pixels_times_edges": {"ms": a2, "ms_per_giga_pixel_edges": 1e9 * d,
                                   "rms_rel_residual": rms_prod, "max_rel_residual": max_prod}}


def bench_scaling(face_counts=(176, 1472, 5000, 26584, 106336, 200000), pixel_sizes=(128, 256, 512, 1024),
                  repeats: int = 3, naive_limit: float = 1.5e8, pixels_for_faces: int | None = None) -> dict:
    """Time and peak memory against faces (at ``pixels_for_faces``^2, default the second of
    ``pixel_sizes``) and against map size (the pillar and the largest dragon up to 26,584
    faces), with log-log slopes, and the cost law (``cost_model``)."""
    import math
    from softshadow import Sun
    from .scenes import RHO, SUN_AZIMUTH, SUN_ELEVATION, SUN_RADIUS_DEG, linear_equivalent_k, scene_grid
    # The sweep's light and linear ramp (the real sun's): the same programs as its cases, compiled once.
    sun, rho = Sun(SUN_AZIMUTH, SUN_ELEVATION), RHO
    k = linear_equivalent_k(math.tan(math.radians(SUN_RADIUS_DEG)))
    s_dir = -np.asarray(sun.light_np)
    pixels = pixels_for_faces or pixel_sizes[min(1, len(pixel_sizes) - 1)]
    meshes = scaling_meshes(face_counts)
    by_faces = [_row(f"{n} faces", m, scene_grid(m, s_dir, pixels), sun, rho, k, repeats, naive_limit)
                for n, m in meshes.items()]
    by_pixels = []
    dragon = max((n for n in meshes if n <= 26584), default=min(meshes))
    for name, mesh in (("pillar", meshes[min(meshes)]), ("dragon", meshes[dragon])):
        for p in pixel_sizes:
            by_pixels.append(_row(f"{name} {p} px", mesh, scene_grid(mesh, s_dir, p), sun, rho, k, repeats,
                                  naive_limit))

    def slopes(rows, x_key, y_key="median_ms"):
        out = {}
        for r in ("softshadow", "paper", "naive"):
            pts = [(row[x_key], row[r][y_key]) for row in rows if row[r].get(y_key) is not None]
            out[r] = loglog_slope([p[0] for p in pts], [p[1] for p in pts])
        return out

    pix = {name: [r for r in by_pixels if r["case"].startswith(name)] for name in ("pillar", "dragon")}
    return {"pixels_for_faces": pixels, "by_faces": by_faces, "slope_vs_faces": slopes(by_faces, "faces"),
            "by_pixels": by_pixels,
            "slope_vs_pixels": {name: slopes(rows, "pixels") for name, rows in pix.items()},
            "memory_slope_vs_faces": slopes(by_faces, "faces", "peak_extra_mb"),
            "memory_slope_vs_pixels": {name: slopes(rows, "pixels", "peak_extra_mb") for name, rows in pix.items()},
            "cost_model": cost_model(by_faces + by_pixels)}
