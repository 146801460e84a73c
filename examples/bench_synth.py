"""Time the table2 preset (physical renderer) and measure render noise against sample counts; print JSON.

Usage: python examples/bench_synth.py [--size 1600x1200] [--sun-samples 64] [--no-noise-table]

Timing: wall time of data_synth.synthesize for table2 (9 photos) and the peak
resident memory of this process. Noise: RMS error of the sun-disk visibility
in a straight edge's penumbra against the analytic occluded-disk profile
(fraction of the lit-umbra step), and RMS relative error of the umbra
brightness from the sky-visibility grids against a 16,384-sample reference.
"""

from __future__ import annotations

import argparse
import json
import math
import resource
import tempfile
import time
from pathlib import Path

import numpy as np
import trimesh

from data_synth import RenderQuality, SunSky, synthesize
from softshadow_cli.synth_command import parse_size
from data_synth.physical import sky_visibility, sky_visibility_map, sun_visibility
from data_synth.receivers import PlaneReceiver
from softshadow import builtin_mesh


def penumbra_noise(n_samples: int, seed: int = 0) -> float:
    """RMS error (visibility units) across a straight edge's penumbra, 2,000 ground points."""
    h, el = 1.0, 40.0
    sun = SunSky(90.0, el, 0.2665)
    plate = trimesh.creation.box(extents=[200.0, 200.0, 0.01])
    plate.apply_translation([-100.0, 0.0, h + 0.005])
    e = math.radians(el)
    x_edge = -h / math.tan(e)
    width = 2 * h * math.tan(sun.radius_rad) / math.sin(e) ** 2
    xs = np.linspace(x_edge - 0.5 * width, x_edge + 0.5 * width, 2000)
    pts = np.stack([xs, np.zeros_like(xs), np.zeros_like(xs)], -1)
    vis = sun_visibility(plate, pts, np.tile([0, 0, 1.0], (len(xs), 1)), sun, n_samples,
                         np.random.default_rng(seed))
    u = np.clip((np.arctan2(h, -xs) - e) / sun.radius_rad, -1, 1)
    ref = 1 - (np.arccos(u) - u * np.sqrt(1 - u * u)) / np.pi
    return float(np.sqrt(np.mean((vis - ref) ** 2)))


def umbra_noise(n_samples: int, reference: np.ndarray, pts: np.ndarray) -> float:
    """RMS relative error of the umbra brightness (rho x open sky) from the interpolated sky grids."""
    mesh = builtin_mesh("pillar")
    smap = sky_visibility_map(mesh, PlaneReceiver(), mesh.bounds, n_samples, seed=1)
    return float(np.sqrt(np.mean((smap.at(pts) / reference - 1) ** 2)))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--size", type=parse_size, default=(1600, 1200))
    ap.add_argument("--sun-samples", type=int, default=64)
    ap.add_argument("--no-noise-table", dest="noise_table", action="store_false")
    args = ap.parse_args()
    out: dict = {"preset": "table2", "renderer": "physical", "size": list(args.size),
                 "sun_samples": args.sun_samples}
    with tempfile.TemporaryDirectory() as tmp:
        t0 = time.perf_counter()
        folder = synthesize(Path(tmp) / "t2", "table2", size=args.size, progress=False,
                            render_quality=RenderQuality(sun_samples=args.sun_samples))
        out["seconds"] = round(time.perf_counter() - t0, 2)
        truth = json.loads((folder / "truth.json").read_text())
        out["photos"] = len(truth["photos_detail"])
        out["render_seconds_per_photo"] = [round(d["render_seconds"], 2) for d in truth["photos_detail"].values()]
        out["sun_rays_per_photo"] = [d["render_stats"]["sun_rays"] for d in truth["photos_detail"].values()]
    out["peak_rss_mb"] = round(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024, 1)
    if args.noise_table:
        out["penumbra_rms_vs_sun_samples"] = {n: round(penumbra_noise(n), 4) for n in (16, 64, 256, 1024)}
        mesh = builtin_mesh("pillar")
        rng = np.random.default_rng(2)
        r = rng.uniform(0.4, 3.0, 200)
        a = rng.uniform(0, 2 * np.pi, 200)
        pts = np.stack([r * np.cos(a), r * np.sin(a), np.zeros_like(r)], -1)
        reference = sky_visibility(mesh, pts, np.tile([0, 0, 1.0], (len(pts), 1)), 16384, seed=9)
        out["umbra_rel_rms_vs_sky_samples"] = {n: round(umbra_noise(n, reference, pts), 4)
                                               for n in (64, 256, 1024, 4096)}
        out["hidden_sky_range"] = [round(float(1 - reference.max()), 4), round(float(1 - reference.min()), 4)]
    print(json.dumps(out, indent=1))


if __name__ == "__main__":
    main()
