"""The paper's Table 1 automated: the expansion ratio S/H of shadow diameters at 0.3, 1.5 and 3 m.

S is the diameter of the whole shadow (soft part included), H that of the hard shadow. A sphere
of diameter ``diameter_m`` is held at each distance d from the ground along the light (sun
azimuth 180 deg, elevation 60 deg, the real sun's disk, rho 0.2) and rendered top-down by the
physical ray caster (``reference``). Measured: across the light, through the shadow's centre,
S is the width where any of the sun's disk is hidden (visible fraction below 0.98) and H where
all of it is (below 0.02), with crossings interpolated between pixels. Predicted: k is fitted to
the same map with this project's renderer (linear profile, rho the truth's, least squares over
the pixels near the shadow), and its outlines give S = D + 2 k d and H = D - 2 k d.
"""

from __future__ import annotations


import numpy as np

__all__ = ["PAPER_TABLE1", "crossing_width", "bench_table1"]

#: The paper's Table 1: distance (m) -> expansion ratio S/H (percent).
PAPER_TABLE1 = {0.3: 101.0, 1.5: 110.0, 3.0: 120.0}


def crossing_width(profile: np.ndarray, level: float, pixel_m: float) -> float:
    """Width (m) of the run of samples below ``level`` around the profile's minimum, with its two
    ends interpolated linearly between samples; 0 when no sample is below."""
    p = np.asarray(profile, np.float64)
    c = int(np.argmin(p))
    if p[c] >= level:
        return 0.0
    i = c
    while i > 0 and p[i - 1] < level:
        i -= 1
    j = c
    while j < len(p) - 1 and p[j + 1] < level:
        j += 1
    left = i - (level - p[i]) / (p[i - 1] - p[i]) if i > 0 else float(i)
    right = j + (level - p[j]) / (p[j + 1] - p[j]) if j < len(p) - 1 else float(j)
    return (right - left) * pixel_m


def bench_table1(distances=(0.3, 1.5, 3.0), diameter_m: float = 0.3, pixels: int = 512,
                 samples: int = 512, elevation_deg: float = 60.0) -> list[dict]:
    import trimesh
    from scipy.optimize import minimize_scalar

    from data_synth import SunSky
    from softshadow import GroundGrid, Pose, ShadowParams, SoftShadowModel, Sun
    from .reference import physical_reference
    light = SunSky.from_rho(180.0, elevation_deg, 0.2)
    s = light.direction
    rows = []
    for d in distances:
        sphere = trimesh.creation.icosphere(subdivisions=4, radius=diameter_m / 2)
        sphere.apply_translation(d * s)  # its centre d metres from the ground along the light
        # Across the light (x here) the shadow keeps its diameter; along it, it stretches.
        extent = 2.0 * diameter_m
        grid = GroundGrid.around((0.0, 0.0), extent, pixels)
        ref = physical_reference(sphere, light, grid, samples)
        centre_row = int(np.argmin(np.abs(grid.pixel_centres()[:, 0, 1])))
        vis = ref.sun_visible[centre_row]
        s_m = crossing_width(vis, 0.98, grid.pixel_m)
        h_m = crossing_width(vis, 0.02, grid.pixel_m)
        model = SoftShadowModel.from_mesh(sphere)
        sun = Sun(180.0, elevation_deg)
        near = ref.sun_visible < 0.999
        # One plan wide enough for every k searched: the same shapes at each step, so one
        # compilation per sphere instead of one per band size the search passes through.
        k_max = 0.02
        plan = model.plan_grid(sun, Pose(), grid, k_max)

        def loss(k):
            img = np.asarray(model.ground_map(ShadowParams(float(k), light.rho), sun, Pose(), grid, plan=plan))
            return float(np.mean((img - ref.shading)[near] ** 2))

        k = float(minimize_scalar(loss, bounds=(1e-5, k_max), method="bounded",
                                  options={"xatol": 1e-6}).x)
        rows.append({"distance_m": d, "diameter_m": diameter_m, "pixel_m": grid.pixel_m,
                     "measured_S_m": s_m, "measured_H_m": h_m,
                     "measured_ratio_percent": 100.0 * s_m / h_m if h_m > 0 else None,
                     "fitted_k": k, "truth_k": light.range_k,
                     "predicted_ratio_percent": 100.0 * (diameter_m + 2 * k * d) / (diameter_m - 2 * k * d),
                     "paper_ratio_percent": PAPER_TABLE1.get(d)})
    return rows
