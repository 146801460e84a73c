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

__all__ = ["scaling_meshes", "loglog_slope", "bench_scaling"]


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
        row["naive"] = timed(lambda: naive.render(s_dir, grid, k, light_rho), max(1, repeats // 2))
        a = np.asarray(ours())
        row["naive_vs_softshadow_rms"] = float(np.sqrt(np.mean((naive.render(s_dir, grid, k, light_rho) - a) ** 2)))
    else:
        row["naive"] = {"skipped": f"{grid.width * grid.height * edges:.2e} pixel-edge pairs"}
    return row


def bench_scaling(quick: bool = False, repeats: int = 3) -> dict:
    from softshadow import Sun
    from .sweep import scene_grid
    sun, k, rho = Sun(200.0, 40.0), 0.01, 0.2
    s_dir = -np.asarray(sun.light_np)
    face_counts = (176, 1472) if quick else (176, 1472, 5000, 26584, 106336, 200000)
    pixels = 32 if quick else 256
    limit = 2e5 if quick else 1.5e8
    meshes = scaling_meshes(face_counts)
    by_faces = [_row(f"{n} faces", m, scene_grid(m, s_dir, pixels), sun, rho, k, repeats, limit)
                for n, m in meshes.items()]
    by_pixels = []
    for name, mesh in (("pillar", meshes[176]), ("dragon", meshes.get(26584, meshes[1472]))):
        for p in ((16, 32) if quick else (128, 256, 512, 1024)):
            by_pixels.append(_row(f"{name} {p} px", mesh, scene_grid(mesh, s_dir, p), sun, rho, k, repeats, limit))

    def slopes(rows, x_key):
        out = {}
        for r in ("softshadow", "paper", "naive"):
            pts = [(row[x_key], row[r]["median_ms"]) for row in rows if "median_ms" in row[r]]
            out[r] = loglog_slope([p[0] for p in pts], [p[1] for p in pts])
        return out

    return {"pixels_for_faces": pixels, "by_faces": by_faces, "slope_vs_faces": slopes(by_faces, "faces"),
            "by_pixels": by_pixels,
            "slope_vs_pixels": {name: slopes([r for r in by_pixels if r["case"].startswith(name)], "pixels")
                                for name in ("pillar", "dragon")}}
