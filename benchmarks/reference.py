"""Converged physical renders of a top-down ground map, cached on disk (the bench's image truth).

The reference is ``data_synth``'s ray caster (sun disk plus uniform sky, direct light), which
shares no code with the renderer: each pixel's irradiance is averaged over the pixel's area and
the sun's disk with ``n_samples`` stratified rays (two independent halves, whose difference
measures the reference's own noise), the hidden sky from a cosine-weighted hemisphere (a sky
map, traced pixel by pixel next to the object where the map's interpolation fails). Shading
is irradiance over the open-ground lit irradiance, so it reads 1 lit and rho in an open umbra,
the renderer's units.

Renders are cached as ``.npz`` under ``SOFTSHADOW_BENCH_CACHE`` (default
``~/.cache/softshadow/bench``), keyed by the mesh, light, grid and sample count: a report re-made
on the same machine casts its rays once.
"""

from __future__ import annotations

import dataclasses
import hashlib
import os
from pathlib import Path

import numpy as np
import trimesh

from data_synth import PlaneReceiver, SunSky, irradiance, shadow_reach, sky_visibility_map, sun_visibility
from softshadow import GroundGrid

__all__ = ["PhysicalReference", "bench_cache_dir", "physical_reference", "ground_sky", "block_mean"]

# Bump when the reference's definition changes (invalidates the cache). 2: the sky traced per
# pixel where the sky map's interpolation fails (``ground_sky``); the sun's visibility is as in 1,
# so it is read from a version-1 file when there is one.
_VERSION = "2"
_SUN_VERSION = "1"


def bench_cache_dir() -> Path:
    return Path(os.environ.get("SOFTSHADOW_BENCH_CACHE", Path.home() / ".cache" / "softshadow" / "bench"))


@dataclasses.dataclass(frozen=True)
class PhysicalReference:
    """shading (H, W): E / E_lit; sun_visible (H, W): the visible fraction of the sun's disk
    (area-averaged); noise_rms: the reference's own RMS noise in the penumbra band (from its two
    halves); seconds: ray-casting time when it was made (0 if it came from the cache)."""

    shading: np.ndarray
    sun_visible: np.ndarray
    noise_rms: float
    seconds: float

    def band(self, margin: float = 0.01) -> np.ndarray:
        """Pixels (H, W) in the penumbra: part of the sun's disk hidden, part seen."""
        return (self.sun_visible > margin) & (self.sun_visible < 1.0 - margin)


def _key(mesh: trimesh.Trimesh, sun: SunSky, grid: GroundGrid, n_samples: int, version: str = _VERSION) -> str:
    h = hashlib.sha1(version.encode())
    h.update(np.ascontiguousarray(mesh.vertices, dtype=np.float64).tobytes())
    h.update(np.ascontiguousarray(mesh.faces, dtype=np.int64).tobytes())
    h.update(repr((dataclasses.astuple(sun), dataclasses.astuple(grid), int(n_samples))).encode())
    return h.hexdigest()[:20]


def block_mean(image: np.ndarray, factor: int) -> np.ndarray:
    """Mean over factor x factor blocks (H, W) -> (H / factor, W / factor): a centred grid of
    N * factor pixels averaged to the grid of N pixels over the same square."""
    h, w = image.shape
    return image.reshape(h // factor, factor, w // factor, factor).mean(axis=(1, 3))


def ground_sky(mesh: trimesh.Trimesh, pts: np.ndarray, n_samples: int) -> np.ndarray:
    """Open-sky fraction (N,) of ground points pts (N, 3) beside the mesh.

    ``data_synth.sky_visibility_map`` interpolates between nodes several pixels apart (6.5 cm
    for the pillar) and traces point by point the cells whose nodes differ by more than
    ``data_synth.SKY_SPREAD`` (next to the walls, where interpolation read up to 0.65 of the
    sky, 0.13 in shading, too dark; Mitsuba, tracing each pixel, disagreed with the map there).
    """
    return sky_visibility_map(mesh, PlaneReceiver(), mesh.bounds, n_samples=n_samples).at(pts[:, :2])


def physical_reference(mesh: trimesh.Trimesh, sun: SunSky, grid: GroundGrid, n_samples: int = 1024,
                       cache_dir: Path | None = None) -> PhysicalReference:
    """The converged physical render of ``grid`` (top-down, ground z = 0), from the cache when there."""
    cache = Path(cache_dir) if cache_dir is not None else bench_cache_dir()
    path = cache / f"reference-{_key(mesh, sun, grid, n_samples)}.npz"
    if path.exists():
        with np.load(path) as f:
            return PhysicalReference(f["shading"], f["sun_visible"], float(f["noise_rms"]), 0.0)
    import time
    t0 = time.perf_counter()
    shape = (grid.height, grid.width)
    pts = grid.pixel_centres().reshape(-1, 3)
    normals = np.tile([0.0, 0.0, 1.0], (len(pts), 1))
    sun_file = cache / f"reference-{_key(mesh, sun, grid, n_samples, _SUN_VERSION)}.npz"
    if sun_file.exists():  # the sun's part is unchanged since that version: its rays are not cast again
        with np.load(sun_file) as f:
            sun_vis, noise = f["sun_visible"].astype(np.float64).reshape(-1), float(f["noise_rms"])
    else:
        sun_vis, noise = _sun_visible(mesh, sun, grid, pts, normals, n_samples)
    e = irradiance(sun, normals, sun_vis, ground_sky(mesh, pts, n_samples))
    shading = (e / sun.lit_irradiance).reshape(shape)
    sun_vis = sun_vis.reshape(shape)
    seconds = time.perf_counter() - t0
    cache.mkdir(parents=True, exist_ok=True)
    tmp = path.with_suffix(".tmp.npz")
    np.savez_compressed(tmp, shading=shading.astype(np.float32), sun_visible=sun_vis.astype(np.float32),
                        noise_rms=noise)
    tmp.replace(path)
    return PhysicalReference(shading.astype(np.float32), sun_vis.astype(np.float32), noise, seconds)


def _sun_visible(mesh, sun: SunSky, grid: GroundGrid, pts: np.ndarray, normals: np.ndarray,
                 n_samples: int) -> tuple[np.ndarray, float]:
    """The sun's visible fraction (N,) at the pixels, averaged over each pixel's area, and the
    RMS noise of the shading in the penumbra band from its two independent halves."""
    reach = shadow_reach(np.asarray(mesh.vertices), sun, pts)
    axes = np.broadcast_to(np.array([[grid.pixel_m, 0.0, 0.0], [0.0, grid.pixel_m, 0.0]]),
                           (int(reach.sum()), 2, 3))
    halves = []
    for seed in (1, 2):  # two independent halves: their mean is the reference, their spread its noise
        vis = np.ones(len(pts))
        if reach.any():
            vis[reach] = sun_visibility(mesh, pts[reach], normals[reach], sun, max(n_samples // 2, 1),
                                        rng=np.random.default_rng(seed), pixel_axes=axes)
        halves.append(vis)
    sun_vis = 0.5 * (halves[0] + halves[1])
    band = (sun_vis > 0.01) & (sun_vis < 0.99)
    diff = (halves[0] - halves[1])[band] * sun.sun_horizontal_irradiance / sun.lit_irradiance
    noise = float(np.sqrt(np.mean(diff ** 2)) / 2.0) if band.any() else 0.0
    return sun_vis, noise
