"""The Shoji paper's figures 19-24 remade: a soft shadow on a range-image background.

Usage: python examples/range_image_figure.py [--out docs/img/range_image.png] [--size 800x600] [--seed 0]

1. data_synth renders the ``depth-background`` preset (the 3 m pillar before a
   rising grassy bank, physical ray casting) and writes each photo's range image.
2. The first photo's range image is back-projected through its camera to 3-D
   receiver points and normals (``fitting.samples.receiver_points``).
3. The model's soft shadow is drawn on those points (k = tan(sun radius) and rho
   of the preset's truth): alpha from the expanded shadow volume, the lit level of
   each point from its normal (``fitting.samples.receiver_light``: sun incidence and the
   sky (1 + n_z) / 2 an open tilted plane sees).
4. Four panels: the range image; the shadow on the range image without the
   background's colours (shading only); with them (the ground texture's albedo
   times the shading); the physical render of the same photo for comparison.
"""

from __future__ import annotations

import argparse
import json
import tempfile
import time
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

from data_synth import GroundAppearance, RenderQuality, procedural_texture, synthesize, texture_coordinates
from fitting.photos.read import read_photo
from fitting.samples.receiver_light import plane_sky_fraction, shadow_factor, sun_incidence
from fitting.samples.receiver_points import ReceiverSurface, read_depth
from fitting.samples.receiver import receiver_plan
from fitting.photos.views import PhotoView
from scene import load_scene
from softshadow import Pose, ShadowParams, SoftShadowModel, Sun, linear_to_srgb
from softshadow.internal import object_mask
from softshadow_cli.synth_command import parse_size


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default="docs/img/range_image.png")
    ap.add_argument("--size", default="800x600", type=parse_size)
    ap.add_argument("--seed", default=0, type=int)
    args = ap.parse_args(argv)
    t0 = time.perf_counter()
    with tempfile.TemporaryDirectory() as tmp:
        folder = synthesize(Path(tmp) / "bank", "depth-background", seed=args.seed, size=args.size,
                            progress=False, render_quality=RenderQuality(sun_samples=32, sky_samples=512))
        truth = json.loads((folder / "truth.json").read_text())
        scene = load_scene(folder / "scene.toml")
        name = sorted(scene.photos)[0]
        photo = read_photo(folder / name)
        detail = truth["photos_detail"][name]
        w, h = args.size
        camera = scene.camera_for(name).pinhole(w, h)
        depth = read_depth(folder / scene.photo(name).depth, (h, w))
    g = truth["groups"][0]
    sun = Sun(detail["sun_azimuth_deg"], detail["sun_elevation_deg"])
    model = SoftShadowModel.from_mesh("pillar", profile="disk")
    pose = Pose()
    view = PhotoView(name, photo.gray, photo.saturated, camera=camera)
    surface = ReceiverSurface("depth", depth=depth)
    rows, cols = np.mgrid[0:h, 0:w]
    pts, nrm, ok, jac = surface.at_pixels(view, cols.ravel(), rows.ravel())
    on_object = object_mask(model.occluder, pose, camera)
    ok &= ~on_object.ravel()
    footprint = np.sqrt(np.linalg.norm(np.cross(jac[ok, :, 0], jac[ok, :, 1]), axis=1))
    plan = receiver_plan(model, sun, pose, pts[ok], nrm[ok], 1.5 * g["range_k"],
                         max(float(np.percentile(footprint, 5)), 1e-4))
    alpha = 1.0 - np.asarray(model.at_points(ShadowParams(g["range_k"], 0.0), sun, pose, pts[ok], plan=plan))
    c = sun_incidence(nrm[ok], -np.asarray(sun.light_np))
    shading = np.full(h * w, np.nan)
    shading[ok] = shadow_factor(alpha, g["rho"], c, plane_sky_fraction(nrm[ok]))
    albedo = np.full((h * w, 3), np.nan, np.float32)
    texture = procedural_texture("concrete", np.random.default_rng([args.seed, 11]))
    albedo[ok] = GroundAppearance(texture).reflectance(texture_coordinates(pts[ok], nrm[ok]))
    shading_img = shading.reshape(h, w)
    colour = albedo.reshape(h, w, 3) * shading_img[..., None]
    sky = np.array([0.75, 0.85, 1.0])
    grey = np.where(np.isfinite(shading_img), shading_img / np.nanpercentile(shading_img, 99.5) * 0.9, 1.0)
    grey[on_object] = 0.35  # the object itself (not drawn by the receiver's model)
    fig, axes = plt.subplots(2, 2, figsize=(11, 8.6))
    ax = axes.ravel()
    im = ax[0].imshow(depth, cmap="viridis")
    fig.colorbar(im, ax=ax[0], fraction=0.035, label="z_cam (m)")
    ax[0].set_title("range image (z along the optical axis)")
    ax[1].imshow(linear_to_srgb(np.clip(grey, 0, 1).astype(np.float32)), cmap="gray", vmin=0, vmax=1)
    ax[1].set_title("soft shadow on the range image, without colours")
    scale = np.nanpercentile(colour, 99.5) / 0.85
    shown = np.where(np.isfinite(colour), np.clip(colour / scale, 0, 1), sky)
    shown[on_object] = 0.35
    ax[2].imshow(linear_to_srgb(shown.astype(np.float32)))
    ax[2].set_title("with the background's colours")
    ax[3].imshow(linear_to_srgb(np.clip(photo.linear / np.percentile(photo.linear, 99), 0, 1)))
    ax[3].set_title("physical render (data_synth) for comparison")
    for a in ax:
        a.set_axis_off()
    fig.suptitle(f"depth-background, seed {args.seed}: k = {g['range_k']:.4f}, rho = {g['rho']:.3f}, "
                 f"sun {sun.azimuth_deg:.0f} / {sun.elevation_deg:.0f} deg")
    fig.tight_layout()
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=90)
    report = {"out": str(out), "size": list(args.size), "seconds": round(time.perf_counter() - t0, 1),
              "range_k": g["range_k"], "rho": g["rho"]}
    print(json.dumps(report))
    return report


if __name__ == "__main__":
    main()
