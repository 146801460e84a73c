"""``softshadow bench --what floor``: the renderer's error floor against physics, before and after.

A pillar's shadow on a top-down 512 x 512 ground map (the sweep's scene: sun azimuth 200 deg,
elevation 40 deg, the real sun's disk, rho = 0.2, i.e. sky irradiance 0.25 of the sun's on open
ground) against the converged physical render of ``reference`` (4096 rays per pixel), for the
renderer's options in one run: ``before`` samples pixel centres and models no hidden sky nor
corners (the renderer until 2026-11-24), ``footprint`` and ``sky`` add one term each,
``after`` both (the default), ``corners`` both and the outline corners' wedge (an option). Errors are ``sweep.image_error``'s (whole map and penumbra band, the object's footprint
left out) plus the share of the squared error within 1 m of the pillar; times are the median
forward render (plan included, as a caller without a plan pays) after compilation, with the
hidden sky kept from the first call (``first_call_s`` is that call, which casts it).

``wedge``: the same 512 x 512 scene for the pillar, the ball and the real dragon, the default
model (footprint and hidden sky) with the ``edge`` rule (linear and disk profiles) against the
``wedge`` rule (disk and linear), timed round-robin per mesh; ``times_edge`` is each case's time
over the edge rule's linear case on the same mesh.
"""

from __future__ import annotations

import math
import time

import numpy as np

from .meshes import bench_mesh
from .scenes import SUN_RADIUS_DEG, BenchScene, SweepSettings, image_error, linear_equivalent_k

__all__ = ["RULE_CASES", "VARIANTS", "bench_floor", "bench_rules"]

# (footprint, hidden sky, corners); "corners" adds the outline corners' wedge (off by default).
VARIANTS = {"before": (False, False, False), "footprint": (True, False, False), "sky": (False, True, False),
            "after": (True, True, False), "corners": (True, True, True)}


# (rule, profile) of ``bench_rules``: the first is the baseline of ``times_edge``.
RULE_CASES = (("edge", "linear"), ("edge", "disk"), ("wedge", "disk"), ("wedge", "linear"))


def bench_rules(meshes=("pillar", "ball", "dragon"), quick: bool = False, repeats: int | None = None,
                progress=print) -> dict:
    """Per mesh, error and forward time of each of ``RULE_CASES`` (default model), round-robin."""
    from softshadow import ShadowParams
    settings = SweepSettings(quick=quick)
    repeats = repeats or (3 if quick else 15)
    k_true = math.tan(math.radians(SUN_RADIUS_DEG))
    out = {}
    for mesh in meshes:
        progress(f"bench floor: the rules on {mesh}")
        scene = BenchScene(bench_mesh(mesh), settings, name=mesh)
        grid = scene.grid(settings.base_pixels)
        cases = {}
        for rule, profile in RULE_CASES:
            params = ShadowParams(k_true if profile == "disk" else linear_equivalent_k(k_true), scene.light.rho)
            model = scene.model_for(profile, rule)
            forward = (lambda m=model, p=params: m.ground_map(p, scene.sun, scene.pose, grid).block_until_ready())
            forward()  # compiles, and casts the hidden sky
            cases[(rule, profile)] = (forward, [], [])
        for _ in range(repeats):
            for forward, wall, cpu in cases.values():
                t0, c0 = time.perf_counter(), time.process_time()
                forward()
                wall.append(time.perf_counter() - t0)
                cpu.append(time.process_time() - c0)
        rows = {}
        for (rule, profile), (forward, wall, cpu) in cases.items():
            err = image_error(np.asarray(forward()), grid, scene.reference, scene.ref_grid, scene.footprint)
            rows[f"{rule}_{profile}"] = {"rule": rule, "profile": profile, "forward_ms": 1e3 * float(np.median(wall)),
                                         "cpu_ms": 1e3 * float(np.median(cpu)), **err}
        base = rows["edge_linear"]
        for r in rows.values():
            r["times_edge"] = r["forward_ms"] / base["forward_ms"]
            r["cpu_times_edge"] = r["cpu_ms"] / base["cpu_ms"]
        out[mesh] = {"faces": scene.faces, "pixels": settings.base_pixels, "reference_samples": scene.samples,
                     **rows}
    return out


def _near_share(image, scene, grid, metres: float = 1.0) -> float:
    """Share of the squared error (whole map, footprint left out) within ``metres`` of the pillar's axis."""
    ref = scene.reference.shading.astype(np.float64)
    keep = ~scene.footprint(scene.ref_grid)
    d2 = (np.asarray(image, np.float64) - ref) ** 2 * keep
    centres = scene.ref_grid.pixel_centres()
    near = np.hypot(centres[..., 0], centres[..., 1]) <= metres
    return float(d2[near].sum() / max(d2.sum(), 1e-300))


def bench_floor(quick: bool = False, progress=print) -> dict:
    """Error against the physical reference and forward time of each variant and profile (JSON-ready)."""
    import jax
    from softshadow import ShadowParams
    settings = SweepSettings(quick=quick)
    repeats = 3 if quick else 15
    progress("bench floor: the physical reference of the pillar")
    scene = BenchScene(bench_mesh("pillar"), settings, name="pillar")
    grid = scene.grid(settings.base_pixels)
    k_true = math.tan(math.radians(SUN_RADIUS_DEG))
    models, out = {}, {}
    for profile in ("linear", "disk"):
        k = k_true if profile == "disk" else linear_equivalent_k(k_true)
        params = ShadowParams(k, scene.light.rho)
        for name, (footprint, sky, corners) in VARIANTS.items():
            model = scene.model.with_options(profile=profile, footprint=footprint, hidden_sky=sky,
                                             corners=corners)
            forward = (lambda m=model, p=params: m.ground_map(p, scene.sun, scene.pose, grid).block_until_ready())
            t0 = time.perf_counter()
            forward()  # compiles, and casts the hidden sky
            models[(profile, name)] = (forward, time.perf_counter() - t0)
    # Timed round-robin, so that every variant sees the same load.
    samples = {key: [] for key in models}
    for _ in range(repeats):
        for key, (forward, _) in models.items():
            t0 = time.perf_counter()
            forward()
            samples[key].append(time.perf_counter() - t0)
    for (profile, name), (forward, first) in models.items():
        image = np.asarray(forward())
        err = image_error(image, grid, scene.reference, scene.ref_grid, scene.footprint)
        err["near_1m_share"] = _near_share(image, scene, grid)
        out.setdefault(profile, {})[name] = {"forward_ms": 1e3 * float(np.median(samples[(profile, name)])),
                                             "first_call_s": first, **err}
    for rows in list(out.values()):
        rows["after_over_before_time"] = rows["after"]["forward_ms"] / rows["before"]["forward_ms"]
        rows["corners_time_ratio"] = rows["corners"]["forward_ms"] / rows["after"]["forward_ms"]
    return {"scene": {"mesh": "pillar", "pixels": settings.base_pixels, "pixel_m": grid.pixel_m,
                      "sun_azimuth_deg": scene.sun.azimuth_deg.item(), "sun_elevation_deg": scene.sun.elevation_deg.item(),
                      "rho": scene.light.rho, "reference_samples": scene.samples,
                      "reference_noise_rms_band": scene.reference.noise_rms, "repeats": repeats,
                      "dtype": str(jax.numpy.result_type(float))},
            **out, "wedge": bench_rules(quick=quick, progress=progress)}
