"""The Mitsuba 3 peer (optional extra ``softshadow[peers]``): the bench's scene path-traced at
several samples per pixel, timed and compared with the same physical truth as every renderer.

The scene: the mesh on a Lambertian ground plane (albedo 0.8, z = 0), a uniform sun disk of the
sun's radius and normal irradiance 1, and a uniform sky, direct light only (``direct``
integrator: light and BSDF samples combined by multiple importance sampling, no
interreflections), seen top-down by an orthographic camera over the bench's ground square with a
box pixel filter (pixel areas integrated, as the truth's). Shading is radiance over the open
ground's lit radiance (albedo / pi x (E_sun + E_sky)), the renderer's units. The ground lies
Mitsuba's shadow-ray offset (about 0.1-0.2 mm) below z = 0, so that its shadow rays start where
the truth's do (``_ray_offset_m``).

``MitsubaSetup`` says how Mitsuba samples that light: the sun as a disk area light far away
beside a ``constant`` sky, or sun and sky in one importance-sampled environment map; the
sampler; the sun's share of the light samples; light and BSDF samples per camera sample; RGB or
mono. ``compare_setups`` measures them against each other and ``EFFICIENT`` is the one that
reached a given noise fastest on the bench's scenes.

``llvm_ad_rgb`` / ``llvm_ad_mono`` are used where their LLVM renders (it needs a newer system
libLLVM than some distributions ship, such as Debian's ``libllvm19``; with Debian 12's libLLVM 15
drjit's code generation aborts the process), checked in a child process; otherwise ``scalar_rgb``,
several times slower. drjit reads the library's path from ``DRJIT_LIBLLVM_PATH``: a newer
libLLVM, such as the one a Rust toolchain ships (``~/.rustup/toolchains/*/lib/libLLVM*.so*``,
LLVM 22), makes the LLVM variants render on such a system.
"""

from __future__ import annotations

import dataclasses
import math
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Literal

import numpy as np

__all__ = ["EFFICIENT", "PLAIN", "MitsubaScene", "MitsubaSetup", "bench_mitsuba", "compare_setups", "mitsuba_available",
           "mitsuba_variant", "render_mitsuba", "time_to_reach"]

ALBEDO = 0.8
# The disk light stands at a finite distance, so each ground point sees the sun from a slightly
# different direction: up to x / distance radians at x metres from the origin. At 1 km that
# parallax was 0.13 deg at the 3 m pillar's shadow tip (3.6 m out), half the sun's radius: the
# tip moved by about 17 mm (2 pixels of 7.6 mm) and Mitsuba's penumbra-band error levelled off at
# 0.060 against the truth, whose sun is at infinity. At 100 km it is 0.0013 deg; float32 still
# resolves the 465 m disk there.
SUN_DISTANCE_M = 1.0e5
_LLVM: list[bool] = []


def mitsuba_available() -> bool:
    try:
        import mitsuba  # noqa: F401
    except ImportError:
        return False
    return True


#: A tiny render with the ``llvm_ad_rgb`` variant (``_llvm_renders``).
_LLVM_PROBE = """
import mitsuba as mi, numpy as np
mi.set_variant("llvm_ad_rgb")
scene = mi.load_dict({"type": "scene", "e": {"type": "constant"}, "i": {"type": "direct"},
                      "s": {"type": "orthographic", "film": {"type": "hdrfilm", "width": 2, "height": 2}}})
np.asarray(mi.render(scene, spp=1))
"""


def _llvm_renders() -> bool:
    """Whether the ``llvm_ad_*`` variants render here (checked once per process)."""
    if not _LLVM:
        import mitsuba as mi
        _LLVM.append("llvm_ad_rgb" in mi.variants() and _runs_in_child(_LLVM_PROBE))
    return _LLVM[0]


def _runs_in_child(code: str, timeout_s: float = 600.0) -> bool:
    """Whether Python ``code`` runs to its end in a child process. An LLVM that drjit cannot use
    aborts the process that renders (no exception reaches Python): the bench's own process, with
    every result it holds, must not be the one."""
    try:
        done = subprocess.run([sys.executable, "-c", code], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                              timeout=timeout_s)
    except (OSError, subprocess.TimeoutExpired):
        return False
    return done.returncode == 0


def mitsuba_variant(mono: bool = False) -> str:
    """Set and return the variant: ``llvm_ad_mono`` (``mono``) or ``llvm_ad_rgb`` where LLVM
    renders, else ``scalar_rgb``."""
    import mitsuba as mi
    chosen = ("llvm_ad_mono" if mono else "llvm_ad_rgb") if _llvm_renders() else "scalar_rgb"
    if mi.variant() != chosen:
        mi.set_variant(chosen)
    return chosen


_Sun = Literal["disk", "envmap"]
_Sampler = Literal["independent", "stratified", "multijitter", "orthogonal", "ldsampler"]


@dataclasses.dataclass(frozen=True)
class MitsubaSetup:
    """How Mitsuba renders the bench's scene; every set-up renders the same light.

    sun: ``disk``, a uniform disk area light ``SUN_DISTANCE_M`` away beside a ``constant`` sky
        emitter (the emitter for a sample picked by ``sun_share``); ``envmap``, one environment
        map holding the sun's disk and the sky, importance-sampled as a whole (see
        ``_sun_sky_envmap``).
    sampler: Mitsuba's sampler plugin.
    sun_share: ``disk`` only: the share of emitter samples given to the sun (Mitsuba's emitter
        ``sampling_weight``); None picks the two emitters alike, Mitsuba's default.
    mono: the ``llvm_ad_mono`` variant (one channel) instead of ``llvm_ad_rgb``: the scene is grey.
    emitter_samples, bsdf_samples: the ``direct`` integrator's light and BSDF samples per camera
        sample (their shadow rays share the camera ray and the pixel sample).
    ground_at_ray_offset: lower the ground by Mitsuba's shadow-ray offset (``_ray_offset_m``), so
        that its shadow rays leave from z = 0 as the truth's do; False leaves the ground at z = 0.
    """

    sun: _Sun = "disk"
    sampler: _Sampler = "ldsampler"
    sun_share: float | None = None
    mono: bool = False
    emitter_samples: int = 1
    bsdf_samples: int = 1
    ground_at_ray_offset: bool = True

    def __post_init__(self):
        if self.sun_share is not None and not (0.0 < self.sun_share < 1.0):
            raise ValueError(f"sun_share must be in (0, 1), got {self.sun_share}")
        if self.sun_share is not None and self.sun != "disk":
            raise ValueError("sun_share applies to the disk sun only (the envmap samples by radiance)")

    @property
    def label(self) -> str:
        share = "" if self.sun_share is None else f", sun share {self.sun_share:g}"
        counts = ("" if (self.emitter_samples, self.bsdf_samples) == (1, 1)
                  else f", {self.emitter_samples} light + {self.bsdf_samples} BSDF samples")
        ground = "" if self.ground_at_ray_offset else ", ground at z = 0"
        return f"{self.sun} sun, {self.sampler}{share}{counts}{', mono' if self.mono else ''}{ground}"


# The most efficient set-up measured (docs/speed_vs_error.md, "Mitsuba's set-ups"): the disk sun
# with 4 light samples per camera sample, 80 % of them on the sun, the sky left mostly to the
# cosine-weighted BSDF samples, which suit a uniform sky; multi-jittered strata.
EFFICIENT = MitsubaSetup(sun="disk", sampler="multijitter", sun_share=0.8, emitter_samples=4)
# The set-up before: Mitsuba's defaults for two emitters (one light sample per camera sample,
# the sun and the sky picked alike) with the low-discrepancy sampler.
PLAIN = MitsubaSetup(sun="disk", sampler="ldsampler")


# Mitsuba (float32) starts a shadow ray (1 + max(|x|, |y|, |z|)) x RayEpsilon along the surface
# normal, to clear its own surface: 0.18 mm up at 1 m from the origin. A raised start moves a
# penumbra on the ground by that over tan(elevation), 0.05 of the dragon's 4.1 mm pixel: enough
# that the dragon's penumbra-band error levelled off at 0.0071 against the truth at 1,024 spp
# (noise 0.0030), and at the truth's own noise (0.0033) with the ground lowered by 0.15 mm.
_RAY_EPSILON = 1500 * 2.0 ** -24  # mitsuba.math.RayEpsilon in single precision


def _ray_offset_m(grid) -> float:
    """Mitsuba's shadow-ray offset over ground z = 0, at the mean max(|x|, |y|) of the map's pixels."""
    c = grid.pixel_centres()
    return float((1.0 + np.mean(np.maximum(np.abs(c[..., 0]), np.abs(c[..., 1])))) * _RAY_EPSILON)


# Rows of the environment map inside the sun's radius (the sun sits on the map's pole, so its
# disk is whole rows): Mitsuba interpolates the map bilinearly, so the disk's edge is a ramp one
# row wide, 1/(2 x 16) of the penumbra here.
ENVMAP_SUN_ROWS = 16
ENVMAP_COLUMNS = 4  # the light does not vary around the pole: a few columns hold it


def _envmap_rows(radius_rad: float, rows_inside: int | None = None) -> tuple[int, np.ndarray]:
    """(row count H, sun weight per row (H,)): row y samples polar angle y pi / (H - 1) from the
    sun's centre; the disk's edge falls half-way between rows ``rows_inside`` and the next, the
    sun's rows weigh 1 and the others 0 (Mitsuba's bilinear interpolation makes the edge a ramp)."""
    rows_inside = ENVMAP_SUN_ROWS if rows_inside is None else rows_inside
    h = max(round(math.pi * (rows_inside + 0.5) / radius_rad), 2 * rows_inside + 2) + 1
    weight = np.zeros(h)
    weight[:rows_inside + 1] = 1.0
    return h, weight


def _envmap_sun_integral(radius_rad: float, rows_inside: int | None = None) -> float:
    """Normal irradiance (integral of radiance x cos over the sphere) of the envmap sun of radiance 1,
    as Mitsuba evaluates it: linear in polar angle between rows."""
    rows_inside = ENVMAP_SUN_ROWS if rows_inside is None else rows_inside
    h, weight = _envmap_rows(radius_rad, rows_inside)
    step = math.pi / (h - 1)
    n = rows_inside + 2  # the ramp ends at the first dark row
    theta = np.linspace(0.0, n * step, 64 * n + 1)
    value = np.interp(theta, np.arange(h) * step, weight)
    f = value * np.cos(theta) * np.sin(theta) * 2.0 * math.pi
    return float(np.sum((f[1:] + f[:-1]) / 2.0 * np.diff(theta)))


def _sun_sky_envmap(light) -> tuple[np.ndarray, np.ndarray]:
    """(radiance (H, ENVMAP_COLUMNS, 3) float32, to_world (4, 4)): the sun's disk (normal
    irradiance ``light.sun_normal_irradiance``) plus the uniform sky, the sun on the map's pole
    (Mitsuba's local +y) turned onto ``light.direction``."""
    h, weight = _envmap_rows(light.radius_rad)
    columns = ENVMAP_COLUMNS
    sun = light.sun_normal_irradiance / _envmap_sun_integral(light.radius_rad)
    radiance = light.sky_radiance + sun * weight
    img = np.repeat(np.repeat(radiance[:, None, None], columns, axis=1), 3, axis=2).astype(np.float32)
    d = np.asarray(light.direction, np.float64)
    x = np.cross(d, [0.0, 0.0, 1.0])
    x /= np.linalg.norm(x)
    z = np.cross(x, d)
    to_world = np.eye(4)
    to_world[:3, 0], to_world[:3, 1], to_world[:3, 2] = x, d, z
    return img, to_world


def _scene_dict(mesh_path: Path, light, grid, setup: MitsubaSetup = EFFICIENT) -> dict:
    """Mitsuba scene (dict) of the mesh on the ground under ``light`` (data_synth.SunSky), seen
    top-down over ``grid`` (softshadow.GroundGrid)."""
    import mitsuba as mi
    T = mi.ScalarTransform4f
    d = np.asarray(light.direction, np.float64)
    extent = grid.pixel_m * grid.width
    cx = grid.origin_m[0] + (grid.width - 1) / 2 * grid.pixel_m
    cy = grid.origin_m[1] - (grid.height - 1) / 2 * grid.pixel_m
    scene = {
        "type": "scene",
        "integrator": {"type": "direct", "emitter_samples": setup.emitter_samples,
                       "bsdf_samples": setup.bsdf_samples},
        "sensor": {"type": "orthographic",
                   "to_world": T().look_at(origin=[cx, cy, 50.0], target=[cx, cy, 0.0], up=[0.0, 1.0, 0.0])
                   @ T().scale([extent / 2, extent / 2, 1.0]),
                   "film": {"type": "hdrfilm", "width": grid.width, "height": grid.height,
                            "rfilter": {"type": "box"}, "pixel_format": "luminance"},
                   "sampler": {"type": setup.sampler}},
        "ground": {"type": "rectangle",
                   "to_world": T().translate([0.0, 0.0, -_ray_offset_m(grid) if setup.ground_at_ray_offset else 0.0])
                   @ T().scale([400.0, 400.0, 1.0]),
                   "bsdf": {"type": "diffuse", "reflectance": {"type": "rgb", "value": ALBEDO}}},
        "object": {"type": "ply", "filename": str(mesh_path), "face_normals": True,
                   "bsdf": {"type": "diffuse", "reflectance": {"type": "rgb", "value": 0.5}}},
    }
    if setup.sun == "envmap":
        img, to_world = _sun_sky_envmap(light)
        scene["sun_and_sky"] = {"type": "envmap", "bitmap": mi.Bitmap(img), "to_world": T(to_world.tolist())}
        return scene
    r = light.radius_rad
    solid_angle = 2.0 * math.pi * (1.0 - math.cos(r))
    centre = SUN_DISTANCE_M * d
    up = [0.0, 0.0, 1.0] if abs(d[2]) < 0.99 else [0.0, 1.0, 0.0]
    share = {} if setup.sun_share is None else {"sampling_weight": setup.sun_share}
    sky_share = {} if setup.sun_share is None else {"sampling_weight": 1.0 - setup.sun_share}
    scene["sun"] = {"type": "disk",
                    # The disk faces the scene: its normal (local +z) points back along -d.
                    "to_world": T().look_at(origin=centre.tolist(), target=(centre - d).tolist(), up=up)
                    @ T().scale([SUN_DISTANCE_M * math.tan(r)] * 3),
                    "emitter": {"type": "area", "radiance": {"type": "rgb",
                                                             "value": light.sun_normal_irradiance / solid_angle},
                                **share}}
    scene["sky"] = {"type": "constant", "radiance": {"type": "rgb", "value": light.sky_radiance}, **sky_share}
    return scene


class MitsubaScene:
    """The bench's scene loaded once in Mitsuba; ``render(spp)`` -> shading (H, W), float64."""

    def __init__(self, mesh, light, grid, setup: MitsubaSetup = EFFICIENT):
        import mitsuba as mi
        mitsuba_variant(mono=setup.mono)
        self.setup = setup
        self._tmp = tempfile.TemporaryDirectory()
        path = Path(self._tmp.name) / "object.ply"
        mesh.export(path)
        self.scene = mi.load_dict(_scene_dict(path, light, grid, setup))
        self.lit_radiance = ALBEDO / math.pi * (light.sun_horizontal_irradiance + math.pi * light.sky_radiance)
        self._seed = 0

    def render(self, spp: int) -> np.ndarray:
        import mitsuba as mi
        mitsuba_variant(mono=self.setup.mono)
        self._seed += 1
        img = np.asarray(mi.render(self.scene, spp=int(spp), seed=self._seed), dtype=np.float64)
        img = img.reshape(img.shape[0], img.shape[1], -1).mean(axis=2)
        return img / self.lit_radiance  # row 0 at +y, column 0 at -x: the grid's own layout


def render_mitsuba(mesh, light, grid, spp: int, setup: MitsubaSetup = EFFICIENT) -> np.ndarray:
    """One Mitsuba render of the bench scene: shading (H, W)."""
    return MitsubaScene(mesh, light, grid, setup).render(spp)


def time_to_reach(times_ms, errors, target: float, floor: float = 0.0) -> dict:
    """Time Mitsuba needs for an error of ``target``: interpolated (log-log) between the measured
    points, or extrapolated past the last one with Monte Carlo's noise ~ time^-1/2 above ``floor``
    (the part of the error that more samples do not lower: Mitsuba's bias against the truth and
    the truth's own noise; error^2 = noise^2 + floor^2). ``ms`` is None where the target lies at
    or below the floor; ``at_least_ms`` is then the longest render measured, which did not reach it."""
    t, e = np.asarray(times_ms, float), np.asarray(errors, float)
    order = np.argsort(t)
    t, e = t[order], e[order]
    if e[0] <= target:
        return {"ms": float(t[0]), "how": "at the fewest samples measured"}
    for i in range(1, len(t)):
        if e[i] <= target:
            f = math.log(target / e[i - 1]) / math.log(e[i] / e[i - 1])
            return {"ms": float(math.exp(math.log(t[i - 1]) + f * math.log(t[i] / t[i - 1]))), "how": "interpolated"}
    if target <= floor:
        return {"ms": None, "at_least_ms": float(t[-1]),
                "how": f"not reached: below Mitsuba's floor {floor:.4f} against this truth"}
    if floor > 0.0:
        return {"ms": float(t[-1] * (e[-1] ** 2 - floor ** 2) / (target ** 2 - floor ** 2)),
                "how": f"extrapolated (noise ~ time^-1/2 above the floor {floor:.4f})"}
    return {"ms": float(t[-1] * (e[-1] / target) ** 2), "how": "extrapolated (error ~ time^-1/2)"}


def _band_noise(a: np.ndarray, b: np.ndarray, band: np.ndarray) -> float:
    """RMS noise (band) of one render from two independent ones: RMS(a - b) / sqrt 2."""
    return float(np.sqrt(np.mean((a - b)[band] ** 2) / 2.0)) if band.any() else 0.0


def _floor(error: float, noise: float) -> float:
    """The part of an error that is not the render's own noise (quadrature)."""
    return math.sqrt(max(error ** 2 - noise ** 2, 0.0))


def bench_mitsuba(scene, spps, repeats: int = 1, targets: dict | None = None,
                  setup: MitsubaSetup = EFFICIENT) -> dict:
    """Mitsuba (``setup``) at each spp on the sweep scene ``scene`` (scenes.BenchScene, its grid at
    the truth's size): time (median of ``repeats`` renders after a first render at the same spp,
    which compiles its kernel and is the image compared), error against the truth, and the band's
    noise from the first and a timed render (two independent renders): ``floor_rms_band`` is the
    error that is not noise (Mitsuba's bias against the truth plus the truth's own noise).

    targets: {name: this project's case} whose errors ("rms", "rms_band") Mitsuba should reach."""
    from .measure import timed
    from .scenes import image_error
    grid = scene.ref_grid
    band = scene.reference.band() & ~scene.footprint(grid)
    t0 = time.perf_counter()
    ms = MitsubaScene(scene.mesh, scene.light, grid, setup)
    load_s = time.perf_counter() - t0
    cases = []
    for spp in spps:
        image = ms.render(spp)
        last = []
        timing = timed(lambda: last.append(ms.render(spp)), repeats, warmup=0, memory=False)
        error = image_error(image, grid, scene.reference, grid, scene.footprint)
        noise = _band_noise(image, last[-1], band)
        cases.append({"renderer": "mitsuba", "mesh": scene.name, "spp": int(spp), "pixels": grid.width,
                      "faces": scene.faces, "setup": setup.label, **timing, "error": error,
                      "noise_rms_band": noise, "floor_rms_band": _floor(error["rms_band"], noise)})
    out = {"variant": mitsuba_variant(mono=setup.mono), "setup": dataclasses.asdict(setup), "setup_label": setup.label,
           "scene_load_s": round(load_s, 2), "reference_noise_rms_band": scene.reference.noise_rms,
           "cases": cases}
    times = [c["median_ms"] for c in cases]
    # "noise_band": Mitsuba's band noise alone (as against its own converged render) reaching this
    # renderer's band error against the truth.
    measures = {"rms": ([c["error"]["rms"] for c in cases], 0.0),
                "rms_band": ([c["error"]["rms_band"] for c in cases], cases[-1]["floor_rms_band"]),
                "noise_band": ([c["noise_rms_band"] for c in cases], 0.0)}
    reach = {}
    for name, case in (targets or {}).items():
        reach[name] = {}
        for metric, (errors, floor) in measures.items():
            goal = case["error"]["rms" if metric == "rms" else "rms_band"]
            hit = time_to_reach(times, errors, goal, floor)
            reach[name][metric] = {"target": goal, "softshadow_ms": case["median_ms"], "mitsuba_ms": hit["ms"],
                                   "how": hit["how"],
                                   "ratio": None if hit["ms"] is None else hit["ms"] / case["median_ms"]}
            if hit["ms"] is None:
                reach[name][metric]["ratio_at_least"] = hit["at_least_ms"] / case["median_ms"]
    out["time_to_reach"] = reach
    return out


def compare_setups(scene, setups: dict, spp: int, repeats: int = 2) -> list[dict]:
    """Each of ``setups`` ({name: MitsubaSetup}) on ``scene`` at ``spp``, timed round-robin (so that
    all see the same load): time, band error against the truth, band noise from two independent
    renders, the floor (error that is not noise), and ``efficiency``: 1 / (noise^2 x time) over
    the first set-up's (the time each needs for equal noise, inverted)."""
    from .scenes import image_error
    grid = scene.ref_grid
    band = scene.reference.band() & ~scene.footprint(grid)
    loaded = {name: MitsubaScene(scene.mesh, scene.light, grid, setup) for name, setup in setups.items()}
    first = {name: ms.render(spp) for name, ms in loaded.items()}  # compiles; the image compared
    second, times = {}, {name: [] for name in loaded}
    for _ in range(repeats):
        for name, ms in loaded.items():
            t0 = time.perf_counter()
            second[name] = ms.render(spp)
            times[name].append(time.perf_counter() - t0)
    rows = []
    for name, setup in setups.items():
        error = image_error(first[name], grid, scene.reference, grid, scene.footprint)
        noise = _band_noise(first[name], second[name], band)
        rows.append({"name": name, "setup": setup.label, "mesh": scene.name, "spp": int(spp),
                     "median_ms": 1e3 * float(np.median(times[name])), "error": error, "noise_rms_band": noise,
                     "floor_rms_band": _floor(error["rms_band"], noise),
                     "reference_noise_rms_band": scene.reference.noise_rms})
    base = rows[0]
    for r in rows:
        r["efficiency"] = (base["noise_rms_band"] ** 2 * base["median_ms"]) / (r["noise_rms_band"] ** 2 * r["median_ms"])
    return rows
