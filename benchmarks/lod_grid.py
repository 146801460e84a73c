"""The Dowling paper's grid (its figures 1 and 6-9) measured: ``softshadow bench --what lod-grid``.

The real Stanford dragon (MIT remesh, 41,384 faces; the paper's 69,000 is capped at the
mesh's own count) and its quadric-error levels of detail (5,000, 1,000, 300 faces:
``softshadow.lod_series``) under the paper's four slides (``softshadow.PAPER_SLIDES``: a
spotlight, and the spotlight through sine grids of amplitude 1 at 4 and 15 cycles and of
amplitude 0.5 at 15), thrown by a slide projector beside the camera with its own shadow map
(``softshadow.render_scene``), no sun, an ambient term, as in the paper. Flat shading: a coarse
mesh shows its facets.

The paper judged by eye which slide hides which simplification (its figures 10-11). Here the
judge is SSIM (scikit-image's ``structural_similarity``, Gaussian window of sigma 1.5 as in Wang
et al. 2004) between each level's image and the full mesh's under the same slide, averaged over
the pixels where either image shows the dragon (dilated by 3 pixels: the outline counts). The
images are rendered with 2 x 2 samples per pixel (``render_scene(supersample=2)``; 1 with
``--quick``). A simplification counts as hidden by a slide when that SSIM is at least ``HIDDEN_SSIM``.
"""

from __future__ import annotations

import datetime
import time
from pathlib import Path

import numpy as np

__all__ = ["lod_grid", "HIDDEN_SSIM", "masking_report"]

#: SSIM from which a level counts as hidden by a slide (a threshold, stated in the report).
HIDDEN_SSIM = 0.95

_CAMERA = ((0.9, -3.3, 1.5), (0.0, 0.0, 0.5))  # position, target (metres): a three-quarter view
_PROJECTOR = ((-0.6, -2.8, 2.4), (0.0, 0.0, 0.5))  # beside and above the camera
_PROJECTOR_FOV_DEG = 38.0
_CAMERA_FOV_DEG = 36.0
_AMBIENT = 0.12
_EXPOSURE = 0.9


def _region(obj: np.ndarray, dilate_px: int = 3) -> np.ndarray:
    """The object's pixels (H, W) bool dilated by ``dilate_px``."""
    import cv2
    return cv2.dilate(obj.astype(np.uint8), np.ones((2 * dilate_px + 1,) * 2, np.uint8)) > 0


def _ssim(full: np.ndarray, level: np.ndarray, region: np.ndarray) -> float:
    from skimage.metrics import structural_similarity
    lo, hi = min(full.min(), level.min()), max(full.max(), level.max())
    _, smap = structural_similarity(full, level, data_range=float(hi - lo) or 1.0, gaussian_weights=True,
                                    sigma=1.5, use_sample_covariance=False, full=True)
    return float(smap[region].mean())


def lod_grid(quick: bool = False, report_path=None, progress=None) -> dict:
    """Render the grid, measure SSIM per level and slide, and (with ``report_path``) write the
    Markdown report there and the grid image as ``img/lod_grid.png`` beside it. Returns the JSON:
    faces per level, slides, SSIM (slides x levels), hidden flags, timings."""
    from softshadow import (PAPER_SLIDES, Pose, Projector, SceneLights, SoftShadowModel, look_at_camera,
        lod_series, render_scene, sine_slide)
    from softshadow import one_blas_thread

    from .environment import environment
    from .meshes import mit_dragon
    width, height = (240, 180) if quick else (400, 300)
    # 2 x 2 samples per pixel: an aliased outline would count as a difference of its own.
    supersample = 1 if quick else 2
    mesh = mit_dragon(full=True)
    levels = lod_series(mesh)
    camera = look_at_camera(*_CAMERA, width, height, _CAMERA_FOV_DEG)
    slides = [(a, f, sine_slide(f, a, 256 if quick else 512)) for a, f in PAPER_SLIDES]
    images = np.zeros((len(slides), len(levels), height, width, 3))
    surfaces = []
    seconds = []
    with one_blas_thread():
        for j, level in enumerate(levels):
            model = SoftShadowModel.from_mesh(level.mesh)
            t = time.perf_counter()
            for i, (a, f, slide) in enumerate(slides):
                if progress:
                    progress(f"bench lod-grid: {level.faces} faces, slide amplitude {a} frequency {f}")
                proj = Projector(*_PROJECTOR, slide, fov_deg=_PROJECTOR_FOV_DEG)
                out = render_scene(camera, model, Pose(), SceneLights(ambient=_AMBIENT), None, [proj],
                                   object_albedo=0.85, ground_albedo=0.85, supersample=supersample)
                images[i, j] = np.asarray(out.image)
                if i == 0:  # the object's pixels: any of the pixel's sub-samples on the object
                    obj = np.asarray(out.setup.visible.surface) == 0
                    surfaces.append(obj.reshape(height, supersample, width, supersample).any(axis=(1, 3)))
            seconds.append((time.perf_counter() - t) / len(slides))
    gray = images.mean(axis=-1)
    ssim = np.ones((len(slides), len(levels)))
    region = _region(surfaces[0])
    for j in range(1, len(levels)):
        both = region | _region(surfaces[j])
        for i in range(len(slides)):
            ssim[i, j] = _ssim(gray[i, 0], gray[i, j], both)
    result = {"faces": [lv.faces for lv in levels], "watertight": [lv.watertight for lv in levels],
              "slides": [{"amplitude": a, "frequency": f} for a, f, _ in slides],
              "ssim": np.round(ssim, 4).tolist(), "hidden_threshold": HIDDEN_SSIM,
              "hidden": (ssim >= HIDDEN_SSIM).tolist(), "image_size": [width, height],
              "supersample": supersample,
              "render_seconds_per_image": [round(s, 3) for s in seconds],
              "date_utc": datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%d %H:%M UTC")}
    if report_path:
        report = Path(report_path)
        report.parent.mkdir(parents=True, exist_ok=True)
        img = report.parent / "img" / "lod_grid.png"
        _draw_grid(images, result, img)
        report.write_text(masking_report(result, environment(), f"img/{img.name}"))
        result["report"], result["image"] = str(report), str(img)
    return result


def _draw_grid(images: np.ndarray, result: dict, path: Path) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from softshadow import linear_to_srgb
    rows, cols = images.shape[:2]
    h, w = images.shape[2:4]
    fig, axes = plt.subplots(rows, cols, figsize=(2.6 * cols, 2.6 * rows * h / w + 0.5), squeeze=False)
    for i in range(rows):
        for j in range(cols):
            ax = axes[i, j]
            ax.imshow(np.asarray(linear_to_srgb(np.clip(images[i, j] * _EXPOSURE, 0.0, 1.0))))
            ax.set_xticks([])
            ax.set_yticks([])
            if j:
                ssim = result["ssim"][i][j]
                ax.text(0.03, 0.04, f"SSIM {ssim:.3f}" + (" hidden" if ssim >= result["hidden_threshold"] else ""),
                        transform=ax.transAxes, color="yellow", fontsize=7)
            if i == 0:
                ax.set_title(f"{result['faces'][j]:,} triangles", fontsize=9)
            if j == 0:
                s = result["slides"][i]
                ax.set_ylabel(f"amplitude {s['amplitude']:g}\nfrequency {s['frequency']:g}", fontsize=8)
    fig.tight_layout(pad=0.3)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)


def masking_report(result: dict, env: dict, image: str) -> str:
    """The Markdown report of ``lod_grid``'s JSON: the grid, the SSIM table and which slide hides
    which level."""
    faces = result["faces"]
    thr = result["hidden_threshold"]
    lines = ["# Which slide hides which level of detail (the Dowling paper's figures 6-11, measured)", "",
             "Made by `softshadow bench --what lod-grid --report docs/lod_masking.md` (the image is "
             f"`docs/{image}`); see [level_of_detail.md](level_of_detail.md) for the set-up.", "",
             f"![grid]({image})", "",
             f"Run {result['date_utc']} on a shared {env['machine']['cores']}-core {env['machine']['cpu']}, "
             f"load {env['machine']['load_average_1_5_15_min']} (1, 5, 15 min); images {result['image_size'][0]} x {result['image_size'][1]}"
             f" ({result.get('supersample', 1)} x {result.get('supersample', 1)} samples per pixel); "
             "render time per image (NumPy/OpenCV visibility and projector shadow map, then JAX shading): "
             + ", ".join(f"{f:,} faces {s:.2f} s" for f, s in zip(faces, result["render_seconds_per_image"]))
             + ".", "",
             "SSIM of each level against the full mesh under the same slide, over the dragon's pixels "
             f"(1 = identical; **bold**: hidden, SSIM >= {thr}):", "",
             "| slide (amplitude, frequency) | " + " | ".join(f"{f:,} faces" for f in faces[1:]) + " |",
             "|---|" + "---:|" * (len(faces) - 1)]
    for s, row in zip(result["slides"], result["ssim"]):
        cells = [f"**{v:.3f}**" if v >= thr else f"{v:.3f}" for v in row[1:]]
        lines.append(f"| {s['amplitude']:g}, {s['frequency']:g} | " + " | ".join(cells) + " |")
    lines += ["", "Which slide hides which simplification:", ""]
    for j, f in enumerate(faces[1:], start=1):
        hiding = [f"({s['amplitude']:g}, {s['frequency']:g})" for s, row in zip(result["slides"], result["ssim"])
                  if row[j] >= thr]
        best = int(np.argmax([row[j] for row in result["ssim"]]))
        bs = result["slides"][best]
        lines.append(f"- {f:,} faces: hidden by {', '.join(hiding) if hiding else 'no slide'}; the slide that "
                     f"hides it best is ({bs['amplitude']:g}, {bs['frequency']:g}), SSIM "
                     f"{result['ssim'][best][j]:.3f}.")
    return "\n".join(lines) + "\n"
