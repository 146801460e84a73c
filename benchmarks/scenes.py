"""The benchmark's scenes and error measure, shared by every bench: the settings, the light (the real
sun's disk of radius 0.2665 deg at azimuth 200 deg, elevation 40 deg, rho 0.2), a mesh's scene with its
converged physical truth (``BenchScene``), and RMS errors over the map and the penumbra band.

The renderer's k is the truth tan(r) for the ``disk`` profile and, for the ``linear`` (paper)
profile, the linear ramp closest to the disk's in least squares (about 0.85 tan r).
"""


from __future__ import annotations

import functools
import math

import numpy as np

from .measure import timed
from .meshes import BENCH_MESHES, bench_mesh
from .reference import block_mean, physical_reference

__all__ = ["BenchScene", "RHO", "SUN_AZIMUTH", "SUN_ELEVATION", "SUN_RADIUS_DEG", "SweepSettings", "build_scenes",
           "image_error", "linear_equivalent_k", "scene_grid"]

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
        self.mitsuba_spps = (1, 4) if quick else (16, 64, 256, 1024)
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

@functools.cache
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
    from softshadow import GroundGrid
    from softshadow.internal import project_to_ground
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


class BenchScene:
    """One mesh under the bench's light: the physical reference and the renderer's inputs."""

    def __init__(self, mesh, settings: SweepSettings, truth_mesh=None, name: str | None = None):
        from data_synth import SunSky
        from softshadow import Pose, SoftShadowModel, Sun
        from softshadow.internal import object_mask
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

    def model_for(self, profile: str, rule: str = "edge"):
        """The model with ``profile`` and ``rule``, one per pair: each holds its hidden-sky maps (a
        second or so of ray casting on the dragon), so the cases and the paper's comparison share them."""
        if (profile, rule) not in self._models:
            self._models[(profile, rule)] = self.model.with_options(profile=profile, rule=rule)
        return self._models[(profile, rule)]

    def footprint(self, grid) -> np.ndarray:
        return self._object_mask(self.truth_model.occluder, self.pose, grid)

    def case(self, pixels: int, profile: str = "linear", dtype: str = "float32", repeats: int = 7,
             rule: str = "edge") -> dict:
        """Time and error of one render (plan included, as a caller without a plan pays)."""
        import jax
        from softshadow import ShadowParams
        k_true = math.tan(math.radians(SUN_RADIUS_DEG))
        k = k_true if profile == "disk" else linear_equivalent_k(k_true)
        grid = self.grid(pixels)
        model = self.model_for(profile, rule)
        with jax.enable_x64(dtype == "float64"):
            params = ShadowParams(k, self.light.rho)

            def forward():
                return model.ground_map(params, self.sun, self.pose, grid).block_until_ready()

            timing = timed(forward, repeats)
            image = np.asarray(forward())
        out = {"renderer": "softshadow", "rule": rule, "mesh": self.name, "faces": self.faces, "pixels": pixels,
               "profile": profile,
               "dtype": dtype, "range_k": k, "rho": self.light.rho, **timing}
        out["error"] = image_error(image, grid, self.reference, self.ref_grid, self.footprint)
        return out


def build_scenes(settings: SweepSettings, progress=print) -> tuple[dict, dict]:
    """({"settings", "reference"} of the result, {mesh: BenchScene}) for ``settings.meshes``: each
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
        scenes[name] = BenchScene(bench_mesh(name), settings, name=name)
        ref = scenes[name].reference
        references[name] = {"noise_rms_band": ref.noise_rms, "seconds": round(ref.seconds, 2),
                            "pixels": settings.reference_pixels, "samples": scenes[name].samples,
                            "pixel_m": scenes[name].ref_grid.pixel_m, "band_pixels": int(ref.band().sum())}
    out["reference"] = references
    return out, scenes
