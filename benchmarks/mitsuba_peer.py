"""The Mitsuba 3 peer (optional extra ``softshadow[peers]``): the bench's scene path-traced at
several samples per pixel, timed and compared with the same physical truth as every renderer.

The scene: the mesh on a Lambertian ground plane (albedo 0.8, z = 0), a uniform sun disk (a disk
area light 100 km along the sun's direction, radius distance x tan(sun radius), normal irradiance 1)
and a uniform sky (a ``constant`` emitter whose horizontal irradiance on open ground is the
light's pi L_sky), direct light only (``direct`` integrator: emitter and BSDF sampling, no
interreflections), seen top-down by an orthographic camera over the bench's ground square with a
box pixel filter (pixel areas integrated, as the truth's). Shading is radiance over the open
ground's lit radiance (albedo / pi x (E_sun + E_sky)), the renderer's units.

``llvm_ad_rgb`` is used where its LLVM loads (it needs a newer system libLLVM than some
distributions ship, such as Debian's ``libllvm19``); otherwise ``scalar_rgb``.
"""

from __future__ import annotations

import math
import tempfile
import time
from pathlib import Path

import numpy as np

__all__ = ["mitsuba_available", "mitsuba_variant", "render_mitsuba", "bench_mitsuba", "time_to_reach"]

ALBEDO = 0.8
# The disk light stands at a finite distance, so each ground point sees the sun from a slightly
# different direction: up to x / distance radians at x metres from the origin. At 1 km that
# parallax was 0.13 deg at the 3 m pillar's shadow tip (3.6 m out), half the sun's radius: the
# tip moved by about 17 mm (2 pixels of 7.6 mm) and Mitsuba's penumbra-band error levelled off at
# 0.060 against the truth, whose sun is at infinity. At 100 km it is 0.0013 deg; float32 still
# resolves the 465 m disk there.
SUN_DISTANCE_M = 1.0e5
WARMUP_SPP = 64  # above this, the timed render is the first at its spp (kernel compilation included)
_VARIANT: list[str] = []


def mitsuba_available() -> bool:
    try:
        import mitsuba  # noqa: F401
    except ImportError:
        return False
    return True


def mitsuba_variant() -> str:
    """``llvm_ad_rgb`` if it renders here, else ``scalar_rgb`` (chosen once per process)."""
    if _VARIANT:
        return _VARIANT[0]
    import mitsuba as mi
    chosen = "scalar_rgb"
    if "llvm_ad_rgb" in mi.variants():
        try:
            mi.set_variant("llvm_ad_rgb")
            scene = mi.load_dict({"type": "scene", "e": {"type": "constant"}, "i": {"type": "direct"},
                                  "s": {"type": "orthographic", "film": {"type": "hdrfilm", "width": 2, "height": 2}}})
            np.asarray(mi.render(scene, spp=1))
            chosen = "llvm_ad_rgb"
        except Exception:  # its libLLVM is missing or too old
            chosen = "scalar_rgb"
    mi.set_variant(chosen)
    _VARIANT.append(chosen)
    return chosen


def _scene_dict(mesh_path: Path, light, grid) -> dict:
    """Mitsuba scene (dict) of the mesh on the ground under ``light`` (data_synth.SunSky), seen
    top-down over ``grid`` (softshadow.GroundGrid)."""
    import mitsuba as mi
    T = mi.ScalarTransform4f
    d = np.asarray(light.direction, np.float64)
    r = light.radius_rad
    solid_angle = 2.0 * math.pi * (1.0 - math.cos(r))
    sun_radiance = light.sun_normal_irradiance / solid_angle
    centre = SUN_DISTANCE_M * d
    extent = grid.pixel_m * grid.width
    cx = grid.origin_m[0] + (grid.width - 1) / 2 * grid.pixel_m
    cy = grid.origin_m[1] - (grid.height - 1) / 2 * grid.pixel_m
    up = [0.0, 0.0, 1.0] if abs(d[2]) < 0.99 else [0.0, 1.0, 0.0]
    return {
        "type": "scene",
        "integrator": {"type": "direct"},
        "sensor": {"type": "orthographic",
                   "to_world": T().look_at(origin=[cx, cy, 50.0], target=[cx, cy, 0.0], up=[0.0, 1.0, 0.0])
                   @ T().scale([extent / 2, extent / 2, 1.0]),
                   "film": {"type": "hdrfilm", "width": grid.width, "height": grid.height,
                            "rfilter": {"type": "box"}, "pixel_format": "luminance"},
                   "sampler": {"type": "ldsampler"}},
        "ground": {"type": "rectangle", "to_world": T().scale([400.0, 400.0, 1.0]),
                   "bsdf": {"type": "diffuse", "reflectance": {"type": "rgb", "value": ALBEDO}}},
        "object": {"type": "ply", "filename": str(mesh_path), "face_normals": True,
                   "bsdf": {"type": "diffuse", "reflectance": {"type": "rgb", "value": 0.5}}},
        "sun": {"type": "disk",
                # The disk faces the scene: its normal (local +z) points back along -d.
                "to_world": T().look_at(origin=centre.tolist(), target=(centre - d).tolist(), up=up)
                @ T().scale([SUN_DISTANCE_M * math.tan(r)] * 3),
                "emitter": {"type": "area", "radiance": {"type": "rgb", "value": sun_radiance}}},
        "sky": {"type": "constant", "radiance": {"type": "rgb", "value": light.sky_radiance}},
    }


class MitsubaScene:
    """The bench's scene loaded once in Mitsuba; ``render(spp)`` -> shading (H, W), float64."""

    def __init__(self, mesh, light, grid):
        import mitsuba as mi
        mitsuba_variant()
        self._tmp = tempfile.TemporaryDirectory()
        path = Path(self._tmp.name) / "object.ply"
        mesh.export(path)
        self.scene = mi.load_dict(_scene_dict(path, light, grid))
        self.lit_radiance = ALBEDO / math.pi * (light.sun_horizontal_irradiance + math.pi * light.sky_radiance)
        self._seed = 0

    def render(self, spp: int) -> np.ndarray:
        import mitsuba as mi
        self._seed += 1
        img = np.asarray(mi.render(self.scene, spp=int(spp), seed=self._seed), dtype=np.float64)
        img = img.reshape(img.shape[0], img.shape[1], -1).mean(axis=2)
        return img / self.lit_radiance  # row 0 at +y, column 0 at -x: the grid's own layout


def render_mitsuba(mesh, light, grid, spp: int) -> np.ndarray:
    """One Mitsuba render of the bench scene: shading (H, W)."""
    return MitsubaScene(mesh, light, grid).render(spp)


def time_to_reach(times_ms, errors, target: float) -> dict:
    """Time Mitsuba needs for an error of ``target``: interpolated (log-log) between the measured
    points, or extrapolated past the last one with Monte Carlo's error ~ time^-1/2."""
    t, e = np.asarray(times_ms, float), np.asarray(errors, float)
    order = np.argsort(t)
    t, e = t[order], e[order]
    if e[0] <= target:
        return {"ms": float(t[0]), "how": "at the fewest samples measured"}
    for i in range(1, len(t)):
        if e[i] <= target:
            f = math.log(target / e[i - 1]) / math.log(e[i] / e[i - 1])
            return {"ms": float(math.exp(math.log(t[i - 1]) + f * math.log(t[i] / t[i - 1]))), "how": "interpolated"}
    return {"ms": float(t[-1] * (e[-1] / target) ** 2), "how": "extrapolated (error ~ time^-1/2)"}


def bench_mitsuba(scene, spps, repeats: int = 1, targets: dict | None = None) -> dict:
    """Mitsuba at each spp on the sweep scene ``scene`` (scenes.BenchScene, its grid at the truth's
    size): time (median of ``repeats`` after a warm-up render) and error against the truth.

    targets: {name: this project's case} whose errors ("rms", "rms_band") Mitsuba should reach."""
    from .measure import timed
    from .scenes import image_error
    grid = scene.ref_grid
    t0 = time.perf_counter()
    ms = MitsubaScene(scene.mesh, scene.light, grid)
    load_s = time.perf_counter() - t0
    cases = []
    for spp in spps:
        # Each spp compiles its own kernel (about 1-2 s here): a warm-up render first, except above
        # WARMUP_SPP, where a render takes a minute or more, the compilation is a few per cent of
        # it and a second render would double the run.
        # Its peak memory is not reported: measuring it would cost one more render.
        timing = timed(lambda: ms.render(spp), repeats, warmup=1 if spp <= WARMUP_SPP else 0, memory=False)
        timing["warmed_up"] = spp <= WARMUP_SPP
        image = ms.render(spp)
        cases.append({"renderer": "mitsuba", "mesh": scene.name, "spp": int(spp), "pixels": grid.width,
                      "faces": scene.faces, **timing,
                      "error": image_error(image, grid, scene.reference, grid, scene.footprint)})
    out = {"variant": mitsuba_variant(), "scene_load_s": round(load_s, 2), "cases": cases}
    reach = {}
    for name, case in (targets or {}).items():
        reach[name] = {}
        for metric in ("rms", "rms_band"):
            goal = case["error"][metric]
            hit = time_to_reach([c["median_ms"] for c in cases], [c["error"][metric] for c in cases], goal)
            reach[name][metric] = {"target": goal, "softshadow_ms": case["median_ms"], "mitsuba_ms": hit["ms"],
                                   "how": hit["how"], "ratio": hit["ms"] / case["median_ms"]}
    out["time_to_reach"] = reach
    return out
