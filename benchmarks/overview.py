"""The plain ``softshadow bench``: every renderer on the three meshes, each with its error.

A small slice of the sweep (``sweep.run_sweep``) that runs in a minute or two on 2 cores: the
pillar, the ball and the real dragon at 128 x 128 against a 1,024-ray physical truth of the same
map (cached on disk), rendered by

- this renderer (linear profile, float32), top-level keys ``pillar``, ``ball``, ``dragon``;
- its ``wedge`` rule (the sun's hidden fraction from the silhouette edges, disk profile, float32),
  ``wedge`` (one case per mesh);
- the Shoji paper's own algorithm, hard and soft (its range and expansion fitted to the truth),
  ``paper`` (laid out as the sweep's ``paper.table3``);
- the naive renderer (every pixel against every silhouette edge), ``naive``;
- Mitsuba 3 at 4, 16 and 64 samples per pixel where it is installed, ``mitsuba``
  (``{"skipped": ...}`` otherwise), with the time it needs to reach this renderer's error.

Every timed case carries its ``error`` against the truth; ``summary`` lists them all, one row
per renderer and mesh, with the time as a multiple of this renderer's on the same mesh.
"""

from __future__ import annotations

import math


from .measure import timed
from .scenes import SUN_RADIUS_DEG, SweepSettings, build_scenes, image_error, linear_equivalent_k
from .sweep import mitsuba_sweep

__all__ = ["OVERVIEW_MESHES", "overview_settings", "naive_case", "run_overview", "summary_rows"]

OVERVIEW_MESHES = ("pillar", "ball", "dragon")


def overview_settings(quick: bool = False) -> SweepSettings:
    """Sizes of the plain bench: 128 px maps against a 1,024-ray truth, 5 repeats; ``quick``
    uses the sweep's quick sizes (64 px, 64 rays, one repeat)."""
    s = SweepSettings(quick=quick)
    if not quick:
        s.reference_pixels = s.base_pixels = 128
        s.reference_samples = 1024
        s.repeats = 5
        # At 128 px the paper's fitted range is a pixel or two (at 512 px it was 1-2 px).
        s.paper_ranges = tuple(range(0, 11))
        s.mitsuba_spps = (4, 16, 64)
    s.meshes = s.mitsuba_meshes = OVERVIEW_MESHES
    return s


def naive_case(scene, pixels: int, repeats: int) -> dict:
    """Time and error of the naive renderer (``naive.NaiveRenderer``) on a sweep scene, with the
    same linear ramp as this renderer's linear case."""
    from .naive import NaiveRenderer
    grid = scene.grid(pixels)
    k = linear_equivalent_k(math.tan(math.radians(SUN_RADIUS_DEG)))
    naive = NaiveRenderer(scene.mesh)
    s_dir = scene.light.direction

    def run():
        return naive.render(s_dir, grid, k, scene.light.rho)

    image = run()  # NumPy compiles nothing: this first run is the image compared, not a warm-up
    timing = timed(run, repeats, warmup=0)
    return {"renderer": "naive", "mesh": scene.name, "faces": scene.faces, "pixels": pixels, "range_k": k,
            "silhouette_edges": naive.silhouette_edges(s_dir), **timing,
            "error": image_error(image, grid, scene.reference, scene.ref_grid, scene.footprint)}


def summary_rows(result: dict) -> list[dict]:
    """One row per timed renderer and mesh: time, errors and time / this renderer's time."""
    rows = []
    for mesh in OVERVIEW_MESHES:
        ours = result[mesh]
        cases = [("softshadow", f"{ours['profile']}, {ours['dtype']}", ours)]
        wedge = result.get("wedge", {}).get(mesh)
        if wedge:
            cases.append(("softshadow (wedge)", f"{wedge['profile']}, {wedge['dtype']}", wedge))
        paper = result["paper"]["table3"][mesh]
        fit = paper["fitted_to_truth"]
        cases += [("paper (hard)", "stencil volume", paper["hard"]),
                  ("paper", f"range {fit['range_px']:g} px, expansion {fit['expand']:g}", paper["soft"]),
                  ("naive", f"{result['naive'][mesh]['silhouette_edges']} silhouette edges", result["naive"][mesh])]
        run = result["mitsuba"].get(mesh)
        if run:
            cases += [("mitsuba", f"{c['spp']} spp", c) for c in run["cases"]]
        for renderer, setting, c in cases:
            rows.append({"mesh": mesh, "renderer": renderer, "setting": setting, "pixels": c.get("pixels", ours["pixels"]),
                         "median_ms": c["median_ms"], "times_softshadow": c["median_ms"] / ours["median_ms"],
                         "rms": c["error"]["rms"], "rms_band": c["error"]["rms_band"]})
    return rows


def run_overview(settings: SweepSettings, progress=print) -> dict:
    """The plain bench's result (module docstring): JSON-ready."""
    from .paper import bench_paper_table3
    out, scenes = build_scenes(settings, progress)
    for name, scene in scenes.items():
        progress(f"bench: this renderer on {name}")
        out[name] = scene.case(settings.base_pixels, repeats=settings.repeats)
    out["wedge"] = {}
    for name, scene in scenes.items():
        progress(f"bench: this renderer's wedge rule on {name}")
        out["wedge"][name] = scene.case(settings.base_pixels, profile="disk", rule="wedge", repeats=settings.repeats)
    progress("bench: the paper's algorithm (hard, and soft fitted to the truth)")
    out["paper"] = {"table3": bench_paper_table3(scenes, settings)}
    out["naive"] = {}
    for name, scene in scenes.items():
        progress(f"bench: the naive renderer on {name}")
        # Seconds a render on the dragon, and its spread is small beside that: one timed run.
        out["naive"][name] = naive_case(scene, settings.base_pixels, 1)
    out["mitsuba"] = mitsuba_sweep(scenes, out, settings, progress)
    out["summary"] = summary_rows(out)
    return out
