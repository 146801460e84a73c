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

import functools
import math

import numpy as np

from .measure import timed
from .meshes import BENCH_MESHES, bench_mesh, decimated
from .reference import block_mean, physical_reference

__all__ = ["SweepSettings", "build_scenes", "run_sweep", "linear_equivalent_k", "scene_grid", "image_error"]

SUN_AZIMUTH, SUN_ELEVATION, SUN_RADIUS_DEG, RHO = 200.0, 40.0, 0.2665, 0.2


class SweepSettings:
    """Sizes of a sweep: ``quick`` is a short run (small maps, few rays, one repeat); ``tiny()``
    the smallest that still runs every part (the harness's own test)."""

    def __init__(self, quick: bool = False):
        self.quick = quick
        self.tiny = False
        self.reference_pixels = 64 if quick else 512
        self.reference_samples = 64 if quick else 4096
        # The knot's many silhouette edges make its rays the dearest: fewer (its noise is reported).
        self.reference_samples_for = {} if quick else {"knot": 1024}
        self.base_pixels = 64 if quick else 512
        self.resolutions = (32, 128) if quick else (128, 256, 512, 1024, 2048)
        self.lod_faces = (2000,) if quick else (26584, 10000, 3000, 1000, 300)
        self.repeats = 1 if quick else 7
        self.fit_samples = (300,) if quick else (150, 400, 1300)
        self.fit_seeds = 2 if quick else 12
        self.meshes = ("pillar", "ball", "dragon") if quick else BENCH_MESHES
        # The paper's algorithm, fitted by grid search: its range (pixels) and expansion (L' tilt).
        self.paper_ranges = (0, 2) if quick else tuple(range(0, 41))
        self.paper_expands = (0.0,) if quick else (0.0, 0.002, 0.004, 0.006, 0.008, 0.01, 0.012)
        self.table2_samples = 64 if quick else 1024
        self.table1_pixels, self.table1_samples = (64, 64) if quick else (512, 512)
        self.profiles, self.dtypes = ("linear", "disk"), ("float32", "float64")
        # The Mitsuba peer (when installed): samples per pixel, on these meshes.
        self.mitsuba_spps = (1, 4) if quick else (4, 16, 64, 256)
        self.mitsuba_meshes = ("pillar",) if quick else ("pillar", "dragon")
        # Baseline 6 and the fit's scaling: photos per group and samples per photo (cap).
        self.fit_photos = (1, 2) if quick else (1, 2, 4, 8)
        self.fit_caps = (150, 400) if quick else (150, 400, 1300, 4000)
        self.fit_baseline_seeds = 1 if quick else 2  # an 8-photo group's solve takes seconds
        self.scaling_faces = (176, 1472) if quick else (176, 1472, 5000, 26584, 106336, 200000)
        self.scaling_pixels = (16, 32) if quick else (128, 256, 512, 1024)

    @classmethod
    def tiny(cls) -> "SweepSettings":
        """Every part of the sweep at the least size that runs it (seconds, not minutes)."""
        s = cls(quick=True)
        s.tiny = True
        s.reference_pixels = s.base_pixels = 32
        s.reference_samples = s.table2_samples = 16
        s.resolutions = (32,)  # each new map size is one more compilation
        s.lod_faces = (1000,)
        s.fit_samples = (150,)
        s.table1_pixels, s.table1_samples = 16, 16
        s.mitsuba_spps = (1,)
        s.fit_photos, s.fit_caps, s.fit_baseline_seeds = (1,), (150,), 1
        s.scaling_pixels = (32,)
        # Each profile, precision and mesh level is one more compilation (~3 s on 2 cores).
        s.profiles, s.dtypes, s.lod_faces = ("linear",), ("float32",), ()
        return s

@functools.lru_cache(maxsize=None)
def linear_equivalent_k(k_disk: float) -> float:
    """The linear ramp's k closest (least squares over the penumbra) to a disk profile of k_disk.

    The disk's occluded fraction over u in [-1, 1] against the linear ramp of half-width s; the
    best s is a property of the two shapes (about 0.85), so k scales with it.
    """
    from scipy.optimize import minimize_scalar
    u = np.linspace(-1.5, 1.5, 3001)
    uc = np.clip(u, -1.0, 1.0)
    disk = (np.arccos(uc) - uc * np.sqrt(1.0 - uc * uc)) / np.pi
    res = minimize_scalar(lambda s: np.mean((np.clip(0.5 * (1.0 - u / s), 0.0, 1.0) - disk) ** 2),
                          bounds=(0.3, 1.5), method="bounded")
    return float(res.x) * k_disk


def scene_grid(mesh, sun_direction: np.ndarray, pixels: int, margin: float = 1.1):
    """A square ground grid framing the mesh's footprint and its shadow (GroundGrid)."""
    from softshadow import GroundGrid, project_to_ground
    world = np.asarray(mesh.vertices)
    g = project_to_ground(world, -np.asarray(sun_direction))
    pts = np.vstack([g, world[:, :2]])
    centre = (pts.min(0) + pts.max(0)) / 2
    extent = float((pts.max(0) - pts.min(0)).max()) * margin
    return GroundGrid.around(centre, extent, pixels)


def image_error(image: np.ndarray, grid, reference, ref_grid, footprint_of) -> dict:
    """RMS errors of a render (H, W) on ``grid`` against a reference on ``ref_grid`` (same square).

    footprint_of(grid) -> (H, W) bool: the object's footprint, left out.
    """
    ref, band = reference.shading, reference.band()
    if grid.width >= ref_grid.width:
        f = grid.width // ref_grid.width
        img, cmp_grid = block_mean(np.asarray(image, np.float64), f), ref_grid
    else:
        f = ref_grid.width // grid.width
        img, cmp_grid = np.asarray(image, np.float64), grid
        ref = block_mean(ref.astype(np.float64), f)
        band = block_mean(band.astype(np.float64), f) > 0
    keep = ~footprint_of(cmp_grid)
    d = (img - ref)[keep]
    db = (img - ref)[keep & band]
    return {"rms": float(np.sqrt(np.mean(d ** 2))),
            "rms_band": float(np.sqrt(np.mean(db ** 2))) if db.size else None,
            "max_abs": float(np.max(np.abs(d))), "band_pixels": int(db.size),
            "compared_at": int(cmp_grid.width)}


class _Scene:
    """One mesh under the bench's light: the physical reference and the renderer's inputs."""

    def __init__(self, mesh, settings: SweepSettings, truth_mesh=None, name: str | None = None):
        from data_synth import SunSky
        from softshadow import Pose, SoftShadowModel, Sun, object_mask
        self.mesh = mesh
        self.light = SunSky.from_rho(SUN_AZIMUTH, SUN_ELEVATION, RHO, radius_deg=SUN_RADIUS_DEG)
        self.sun, self.pose = Sun(SUN_AZIMUTH, SUN_ELEVATION), Pose()
        truth = truth_mesh if truth_mesh is not None else mesh
        self.truth_model = SoftShadowModel.from_mesh(truth)
        self.ref_grid = scene_grid(truth, self.light.direction, settings.reference_pixels)
        self.samples = settings.reference_samples_for.get(name, settings.reference_samples)
        self.reference = physical_reference(truth, self.light, self.ref_grid, self.samples)
        self.model = SoftShadowModel.from_mesh(mesh)
        self._models = {}
        self._object_mask = object_mask
        self.faces = int(len(mesh.faces))
        self.name = name

    def grid(self, pixels: int):
        from softshadow import GroundGrid
        g = self.ref_grid
        extent = g.pixel_m * g.width
        centre = (g.origin_m[0] + (g.width - 1) / 2 * g.pixel_m, g.origin_m[1] - (g.height - 1) / 2 * g.pixel_m)
        return GroundGrid.around(centre, extent, pixels)

    def model_for(self, profile: str):
        """The model with ``profile``, one per profile: each holds its hidden-sky maps (a second or
        so of ray casting on the dragon), so the cases and the paper's comparison share them."""
        if profile not in self._models:
            self._models[profile] = self.model.with_options(profile=profile)
        return self._models[profile]

    def footprint(self, grid) -> np.ndarray:
        return self._object_mask(self.truth_model.occluder, self.pose, grid)

    def case(self, pixels: int, profile: str = "linear", dtype: str = "float32", repeats: int = 7) -> dict:
        """Time and error of one render."""
        import jax
        from softshadow import ShadowParams
        k_true = math.tan(math.radians(SUN_RADIUS_DEG))
        k = k_true if profile == "disk" else linear_equivalent_k(k_true)
        grid = self.grid(pixels)
        model = self.model_for(profile)
        with jax.enable_x64(dtype == "float64"):
            params = ShadowParams(k, self.light.rho)

            def forward():
                return model.ground_map(params, self.sun, self.pose, grid).block_until_ready()

            timing = timed(forward, repeats)
            image = np.asarray(forward())
        out = {"renderer": "softshadow", "mesh": self.name, "faces": self.faces, "pixels": pixels, "profile": profile,
               "dtype": dtype, "range_k": k, "rho": self.light.rho, **timing}
        out["error"] = image_error(image, grid, self.reference, self.ref_grid, self.footprint)
        return out


def build_scenes(settings: SweepSettings, progress=print) -> tuple[dict, dict]:
    """({"settings", "reference"} of the result, {mesh: _Scene}) for ``settings.meshes``: each
    mesh under the bench's light with its physical truth (made or read from the cache)."""
    out = {"settings": {"sun_azimuth_deg": SUN_AZIMUTH, "sun_elevation_deg": SUN_ELEVATION,
                        "sun_radius_deg": SUN_RADIUS_DEG, "rho": RHO,
                        "reference_pixels": settings.reference_pixels,
                        "reference_samples": settings.reference_samples, "repeats": settings.repeats,
                        "quick": settings.quick}}
    scenes = {}
    references = {}
    for name in settings.meshes:
        progress(f"bench: reference for {name}")
        scenes[name] = _Scene(bench_mesh(name), settings, name=name)
        ref = scenes[name].reference
        references[name] = {"noise_rms_band": ref.noise_rms, "seconds": round(ref.seconds, 2),
                            "pixels": settings.reference_pixels, "samples": scenes[name].samples,
                            "pixel_m": scenes[name].ref_grid.pixel_m, "band_pixels": int(ref.band().sum())}
    out["reference"] = references
    return out, scenes


def run_sweep(settings: SweepSettings, fit: bool = True, progress=print) -> dict:
    """All sweeps; returns the JSON-ready result (cases grouped by sweep, and per mesh)."""
    out, scenes = build_scenes(settings, progress)
    for name, scene in scenes.items():
        progress(f"bench sweep: {name}")
        out[name] = scene.case(settings.base_pixels, repeats=settings.repeats)
    progress("bench sweep: resolution")
    out["resolution"] = [scenes["pillar"].case(p, repeats=settings.repeats) for p in settings.resolutions]
    progress("bench sweep: profile and dtype")
    out["profile"] = [scenes["pillar"].case(settings.base_pixels, profile=p, repeats=settings.repeats)
                      for p in settings.profiles]
    out["dtype"] = [scenes["pillar"].case(settings.base_pixels, dtype=d, repeats=settings.repeats)
                    for d in settings.dtypes]
    progress("bench sweep: level of detail")
    full = scenes["dragon"].mesh
    out["lod"] = [_Scene(decimated(full, f), settings, truth_mesh=full, name="dragon").case(settings.base_pixels,
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
        result[name] = bench_mitsuba(scenes[name], settings.mitsuba_spps, repeats=1,
                                     targets={"softshadow": out[name]})
    return result


def fit_samples_sweep(settings: SweepSettings) -> list[dict]:
    """Same-model fits (noise over seeds) at several samples per photo: spread against the
    Cramer-Rao bound, and the time per group after compilation."""
    from .fit import bench_same_model
    rows = []
    for n in settings.fit_samples:
        r = bench_same_model(seeds=settings.fit_seeds, max_samples_per_photo=n)
        rows.append({"samples_per_photo": n, **r})
    return rows
