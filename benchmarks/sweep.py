"""``softshadow bench --what sweep``: the renderer's speed against its error, swept.

Every image case renders a top-down ground map of a mesh's soft shadow (sun azimuth 200 deg,
elevation 40 deg, the real sun's disk of radius 0.2665 deg, sky such that rho = 0.2) and is
compared with a converged physical render of the same square (``reference``) at the reference's
resolution: a finer render is block-averaged down to it, a coarser one is compared with the
reference block-averaged down to the render's own (both grids are centred on the same square, so
blocks nest). Errors are RMS of the shading (1 lit, rho umbra) over the whole map and over the
penumbra band (pixels that see part of the sun's disk), the object's own footprint left out.

The renderer's k is the truth tan(r) for the ``disk`` profile and, for the ``linear`` (paper)
profile, the linear ramp closest to the disk's in least squares (about 0.85 tan r).

Sweeps: the meshes (pillar, ball, the real MIT dragon, the procedural knot), resolution, the
penumbra profile, float32 against float64, the dragon's level of detail, and for fits the
samples per photo (same-model data against the Cramer-Rao bound, ``fit.bench_same_model``).
"""

from __future__ import annotations

import dataclasses

from .meshes import decimated
from .scenes import BenchScene, SweepSettings, build_scenes

__all__ = ["MITSUBA_SETUPS", "fit_samples_sweep", "mitsuba_setups_sweep", "mitsuba_sweep", "run_sweep"]


def _mitsuba_setups() -> dict:
    """The Mitsuba set-ups compared (names -> mitsuba_peer.MitsubaSetup), the plain one first."""
    from .mitsuba_peer import EFFICIENT, PLAIN, MitsubaSetup
    return {"plain": PLAIN,
            "multijitter": MitsubaSetup(sampler="multijitter"),
            "envmap": MitsubaSetup(sun="envmap", sampler="multijitter"),
            "sun share 0.8": MitsubaSetup(sampler="multijitter", sun_share=0.8),
            "efficient": EFFICIENT,
            "efficient, ground at z = 0": dataclasses.replace(EFFICIENT, ground_at_ray_offset=False),
            "16 light samples": MitsubaSetup(sampler="multijitter", sun_share=0.9, emitter_samples=16)}


MITSUBA_SETUPS = ("plain", "multijitter", "envmap", "sun share 0.8", "efficient", "efficient, ground at z = 0",
                  "16 light samples")


def run_sweep(settings: SweepSettings, fit: bool = True, progress=print) -> dict:
    """All sweeps; returns the JSON-ready result (cases grouped by sweep, and per mesh)."""
    out, scenes = build_scenes(settings, progress)
    for name, scene in scenes.items():
        progress(f"bench sweep: {name}")
        out[name] = scene.case(settings.base_pixels, repeats=settings.repeats)
    out["wedge"] = {}
    for name, scene in scenes.items():
        progress(f"bench sweep: the wedge rule on {name}")
        out["wedge"][name] = scene.case(settings.base_pixels, profile="disk", rule="wedge", repeats=settings.repeats)
    progress("bench sweep: resolution")
    out["resolution"] = [scenes["pillar"].case(p, repeats=settings.repeats) for p in settings.resolutions]
    progress("bench sweep: profile and dtype")
    out["profile"] = [scenes["pillar"].case(settings.base_pixels, profile=p, repeats=settings.repeats)
                      for p in settings.profiles]
    out["dtype"] = [scenes["pillar"].case(settings.base_pixels, dtype=d, repeats=settings.repeats)
                    for d in settings.dtypes]
    progress("bench sweep: level of detail")
    full = scenes["dragon"].mesh
    out["lod"] = [BenchScene(decimated(full, f), settings, truth_mesh=full, name="dragon").case(settings.base_pixels,
                                                                            repeats=settings.repeats)
                  for f in settings.lod_faces]
    progress("bench sweep: the paper's algorithm (Table 3)")
    from .paper import bench_paper_table2, bench_paper_table3
    out["paper"] = {"table3": bench_paper_table3(scenes, settings)}
    progress("bench sweep: the paper's algorithm fitted to the table2 lights (Table 2)")
    out["paper"]["table2"] = bench_paper_table2(settings)
    progress("bench sweep: Table 1 (expansion ratios)")
    from .table1 import bench_table1
    out["table1"] = bench_table1(pixels=settings.table1_pixels, samples=settings.table1_samples)
    out["mitsuba_setups"] = mitsuba_setups_sweep(scenes, settings, progress)
    out["mitsuba"] = mitsuba_sweep(scenes, out, settings, progress)
    progress("bench sweep: scaling against faces and pixels")
    from .scaling import bench_scaling
    out["scaling"] = bench_scaling(settings.scaling_faces, settings.scaling_pixels,
                                   repeats=settings.repeats if settings.quick else 3,
                                   naive_limit=2e5 if settings.quick else 1.5e8)
    if fit:
        progress("bench sweep: fit samples per photo")
        out["fit_samples"] = fit_samples_sweep(settings)
        progress("bench sweep: the fit with finite differences (baseline 6), photos and samples per group")
        from .fit_baseline import bench_fit_baseline
        out["fit_baseline"] = bench_fit_baseline(settings.fit_photos, settings.fit_caps,
                                                 seeds=settings.fit_baseline_seeds,
                                                 repeats=1 if settings.quick else 2)
    return out


def mitsuba_sweep(scenes: dict, out: dict, settings: SweepSettings, progress=print) -> dict:
    """The Mitsuba peer on ``settings.mitsuba_meshes`` (each against this renderer's case of the
    same mesh in ``out``), or {"skipped": ...} when it is not installed."""
    from .mitsuba_peer import bench_mitsuba, mitsuba_available
    if not mitsuba_available():
        progress("skipped: mitsuba not installed (pip install 'softshadow[peers]')")
        return {"skipped": "mitsuba not installed"}
    result = {}
    for name in settings.mitsuba_meshes:
        progress(f"bench sweep: Mitsuba 3 on {name}")
        targets = {"softshadow": out[name]}
        if name in out.get("wedge", {}):
            targets["softshadow (wedge)"] = out["wedge"][name]
        result[name] = bench_mitsuba(scenes[name], settings.mitsuba_spps, repeats=1, targets=targets)
    return result


def mitsuba_setups_sweep(scenes: dict, settings: SweepSettings, progress=print) -> dict:
    """Mitsuba's set-ups (``MITSUBA_SETUPS``) against each other on ``settings.mitsuba_meshes`` at
    64 spp (4 quick; mitsuba_peer.compare_setups), or {"skipped": ...}."""
    from .mitsuba_peer import compare_setups, mitsuba_available
    if not mitsuba_available():
        return {"skipped": "mitsuba not installed"}
    setups = _mitsuba_setups()
    out = {}
    for name in settings.mitsuba_meshes:
        progress(f"bench sweep: Mitsuba's set-ups on {name}")
        out[name] = compare_setups(scenes[name], setups, 4 if settings.quick else 64,
                                   repeats=1)
    return out


def fit_samples_sweep(settings: SweepSettings) -> list[dict]:
    """Same-model fits (noise over seeds) at several samples per photo: spread against the
    Cramer-Rao bound, and the time per group after compilation."""
    from .fit import bench_same_model
    rows = []
    for n in settings.fit_samples:
        r = bench_same_model(seeds=settings.fit_seeds, max_samples_per_photo=n)
        rows.append({"samples_per_photo": n, **r})
    return rows
