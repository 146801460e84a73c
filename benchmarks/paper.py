"""The Shoji paper's own algorithm measured beside its Tables 2 and 3 (``shoji.ShojiRenderer``).

- ``table3``: hard and soft shadow of the pillar, the ball and the real dragon, timed as the
  paper times them (hard: the stencil volume alone; soft: the whole algorithm), each image
  compared with the physical truth and with this project's renderer at the same light.
- ``table2``: the table2 preset's three lights (sun position, disk radius, rho), rendered top
  down by the physical ray caster, fitted with the paper's algorithm: its range (the intensity
  increment, in shadow-texture pixels), its expansion and the brightness, beside the paper's
  hand-set 6 / 5 / 8 and 110 / 120 / 180 and beside the range predicted from the true k.

The paper's algorithm has no gradient: its parameters are fitted by a grid search over the
expansion and the range (the alpha map), with the lit level and rho solved by linear least
squares at each grid point (the shading is linear in them).
"""

from __future__ import annotations

import math

import numpy as np

from .measure import timed
from .shoji import ShojiRenderer

__all__ = ["PAPER_TABLE3", "fit_shoji", "predicted_range_px", "bench_paper_table3", "bench_paper_table2"]

#: The paper's Table 3 (Pentium 4, 2.8 GHz): faces, hard shadow ms, soft shadow ms.
PAPER_TABLE3 = {"pillar": (176, 121.0, 196.0), "ball": (1472, 267.0, 349.0), "dragon": (26584, 516.0, 622.0)}


def fit_shoji(renderer: ShojiRenderer, sun_direction, grid, observed: np.ndarray, keep: np.ndarray,
              ranges, expands) -> dict:
    """Best (range_px, expand) on the grids, with lit level E and rho by least squares:
    observed ~ E (1 - alpha) + E rho alpha over the pixels ``keep`` (H, W) bool."""
    obs = np.asarray(observed, np.float64)[keep]
    best = None
    for expand in expands:
        stencil = renderer.stencil(sun_direction, grid, float(expand))
        for r in ranges:
            alpha = renderer.texture(stencil, sun_direction, float(r)).alpha[keep]
            design = np.stack([1.0 - alpha, alpha], axis=1)
            coef, *_ = np.linalg.lstsq(design, obs, rcond=None)
            rms = float(np.sqrt(np.mean((design @ coef - obs) ** 2)))
            if best is None or rms < best["rms"]:
                best = {"range_px": float(r), "expand": float(expand), "lit": float(coef[0]),
                        "rho": float(coef[1] / coef[0]) if coef[0] else float("nan"), "rms": rms}
    return best


def predicted_range_px(k_linear: float, height_m: float, elevation_deg: float, pixel_m: float) -> float:
    """The paper's range that gives the model's penumbra width at the shadow's far end.

    A linear ramp of range k behind an occluder top at height h is 2 k h / sin(E) wide across
    the light, 2 k h / sin^2(E) along the ground at the shadow's tip; the paper's soft band is
    ``range`` pixels wide there. So range_px = 2 k h / (sin^2(E) pixel_m).
    """
    s = math.sin(math.radians(elevation_deg))
    return 2.0 * k_linear * height_m / (s * s * pixel_m)


def _images_rms(a: np.ndarray, b: np.ndarray, keep: np.ndarray, band: np.ndarray) -> dict:
    d = (np.asarray(a, np.float64) - np.asarray(b, np.float64))
    return {"rms": float(np.sqrt(np.mean(d[keep] ** 2))),
            "rms_band": float(np.sqrt(np.mean(d[keep & band] ** 2))) if (keep & band).any() else None}


def bench_paper_table3(scenes: dict, settings) -> dict:
    """Hard and soft timings of the paper's algorithm beside Table 3, and its image errors.

    scenes: {"pillar" | "ball" | "dragon": scenes.BenchScene}; the soft shadow uses the range and
    expansion fitted to that scene's physical truth (rho is the truth's).
    """
    from softshadow import ShadowParams
    from .scenes import image_error, linear_equivalent_k
    out = {}
    for name in ("pillar", "ball", "dragon"):
        sc = scenes[name]
        grid = sc.grid(settings.base_pixels)
        renderer = ShojiRenderer(sc.mesh)
        s_dir, rho = sc.light.direction, sc.light.rho
        ref_grid = sc.ref_grid
        keep = ~sc.footprint(ref_grid)
        fit = fit_shoji(renderer, s_dir, ref_grid, sc.reference.shading, keep, settings.paper_ranges,
                        settings.paper_expands)
        hard_t = timed(lambda: renderer.render_hard(s_dir, grid, rho), settings.repeats)
        soft_t = timed(lambda: renderer.render(s_dir, grid, fit["range_px"], rho, fit["expand"]),
                       settings.repeats)
        hard = renderer.render_hard(s_dir, grid, rho)
        soft = renderer.render(s_dir, grid, fit["range_px"], rho, fit["expand"])
        k = linear_equivalent_k(math.tan(sc.light.radius_rad))
        # The renderer as the sweep times it (linear profile, its float precision).
        linear = sc.model_for("linear")
        ours = np.asarray(linear.ground_map(ShadowParams(k, rho), sc.sun, sc.pose, grid))
        band = sc.reference.band() if grid.width == ref_grid.width else np.zeros(hard.shape, bool)
        faces, paper_hard, paper_soft = PAPER_TABLE3[name]
        out[name] = {
            "faces": sc.faces, "paper_faces": faces, "pixels": grid.width,
            "paper_hard_ms": paper_hard, "paper_soft_ms": paper_soft,
            "hard": {"renderer": "paper (hard)", **hard_t,
                     "error": image_error(hard, grid, sc.reference, ref_grid, sc.footprint)},
            "soft": {"renderer": "paper", **soft_t,
                     "error": image_error(soft, grid, sc.reference, ref_grid, sc.footprint)},
            "fitted_to_truth": fit,
            "soft_vs_softshadow": _images_rms(soft, ours, ~sc.footprint(grid), band),
        }
    return out


def bench_paper_table2(settings, seed: int = 0) -> list[dict]:
    """The table2 preset's lights, top-down physical truth, fitted with the paper's algorithm."""
    from data_synth import build_preset
    from fitting import PAPER_TABLE2
    from softshadow import brightness_to_paper
    from .meshes import bench_mesh
    from .reference import physical_reference
    from .scenes import linear_equivalent_k, scene_grid
    plan = build_preset("table2", seed=seed)
    mesh = bench_mesh(plan.mesh)
    height = float(mesh.bounds[1, 2])
    renderer = ShojiRenderer(mesh)
    from softshadow import Pose, SoftShadowModel
    from softshadow.internal import object_mask
    occ = SoftShadowModel.from_mesh(mesh).occluder
    rows, seen = [], set()
    for photo in plan.photos:
        if photo.group in seen:
            continue
        seen.add(photo.group)
        light = photo.light
        grid = scene_grid(mesh, light.direction, settings.reference_pixels)
        ref = physical_reference(mesh, light, grid, settings.table2_samples)
        keep = ~object_mask(occ, Pose(), grid)
        fit = fit_shoji(renderer, light.direction, grid, ref.shading, keep, settings.paper_ranges,
                        settings.paper_expands)
        k_lin = linear_equivalent_k(light.range_k)
        paper_range, paper_brightness = PAPER_TABLE2.get(photo.group, (None, None))
        rows.append({
            "label": photo.group, "sun_azimuth_deg": light.azimuth_deg, "sun_elevation_deg": light.elevation_deg,
            "truth_range_k": light.range_k, "truth_rho": light.rho, "truth_brightness": brightness_to_paper(light.rho),
            "pixels": grid.width, "pixel_m": grid.pixel_m, "reference_noise_rms_band": ref.noise_rms,
            "fitted_range_px": fit["range_px"], "fitted_expand": fit["expand"], "fitted_rho": fit["rho"],
            "fitted_brightness": brightness_to_paper(max(fit["rho"], 0.0)), "fit_rms": fit["rms"],
            "predicted_range_px": predicted_range_px(k_lin, height, light.elevation_deg, grid.pixel_m),
            "paper_range": paper_range, "paper_brightness": paper_brightness})
    return rows
