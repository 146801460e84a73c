"""The Dowling paper's grid measured, and the level of detail its masking chooses: ``softshadow bench --what lod-grid``.

The real Stanford dragon (MIT remesh, 41,384 faces; the paper's 69,000 is capped at the mesh's
own count) and its quadric-error levels of detail, halving down to the paper's 300 faces
(``softshadow.lod_series``), under the paper's four slides (``softshadow.PAPER_SLIDES``: a
spotlight, and the spotlight through sine grids of amplitude 1 at 4 and 15 cycles and of
amplitude 0.5 at 15), thrown by a slide projector beside the camera with its own shadow map, no
sun, an ambient term, as in the paper (``softshadow.MaskingScene``). Flat shading: a coarse mesh
shows its facets. Images 640 x 480 with 2 x 2 samples per pixel (``render_frame``), grey.

1. The measured grid: SSIM (``softshadow.masked_ssim``) of every level against the full mesh
   under each of the paper's slides, over the pixels where either shows the dragon (dilated 3
   pixels). A level counts as hidden at ``HIDDEN_SSIM``.
2. The masking table (``softshadow.measure_masking_table``): the same SSIM on a grid of other
   slides (amplitudes 0.25, 0.75, 1; frequencies 0, 2, 6, 10, 20, 30), its margin its own
   interpolation error. Of the paper's slides only the spotlight (frequency 0) is on that grid.
3. The choice: for each of the paper's slides the level ``MaskingTable.choose`` predicts from the
   table, checked against the measured grid (is its measured SSIM at least the threshold, is it
   the coarsest level that is).
4. With the sun (``--report`` only): the table again at three penumbra widths (k 0.003, 0.01,
   0.03), checked at k 0.006 and 0.02 (between them) under the paper's slides, and an animation
   (``docs/img/lod_animation.gif``): the slide's frequency and amplitude changing, without and
   then with the sun (its k changing too), each frame drawn with the level its table chooses.
"""

from __future__ import annotations

import datetime
import time
from pathlib import Path

import numpy as np

__all__ = ["lod_grid", "masking_report", "LEVELS", "TABLE_AMPLITUDES", "TABLE_FREQUENCIES", "SUN_RANGES_K"]

#: The levels: the full dragon, then halving down to the paper's coarsest.
LEVELS = (20000, 10000, 5000, 2500, 1000, 300)
TABLE_AMPLITUDES = (0.25, 0.75, 1.0)
TABLE_FREQUENCIES = (0.0, 2.0, 6.0, 10.0, 20.0, 30.0)
SUN_RANGES_K = (0.003, 0.01, 0.03)
SUN_CHECK_K = (0.006, 0.02)
_EXPOSURE = 0.9


def lod_grid(quick: bool = False, report_path=None, progress=None) -> dict:
    """Measure the grid and the table, choose per slide, and (with ``report_path``) the sun's
    table, its check and the animation; write the Markdown report there, the grid image as
    ``img/lod_grid.png`` and the animation as ``img/lod_animation.gif`` beside it. Returns the
    JSON: faces per level, the grid (slides, SSIM, hidden), the table, the choices, timings."""
    from softshadow import (HIDDEN_SSIM, PAPER_SLIDES, MaskingScene, SoftShadowModel, lod_series,
                            measure_masking_table, one_blas_thread)
    from softshadow.internal import render_level_image

    from .environment import environment
    from .meshes import mit_dragon
    scene = MaskingScene(width=320, height=240) if quick else MaskingScene()
    scene = _without_sun(scene)
    supersample = 1 if quick else 2
    mesh = mit_dragon(full=True)
    levels = lod_series(mesh, (len(mesh.faces), *((5000, 1000, 300) if quick else LEVELS)))
    models = [(lv.faces, SoftShadowModel.from_mesh(lv.mesh)) for lv in levels]
    frequencies = TABLE_FREQUENCIES[::2] + (TABLE_FREQUENCIES[-1],) if quick else TABLE_FREQUENCIES
    t0 = time.perf_counter()
    with one_blas_thread():
        grid_images = np.zeros((len(PAPER_SLIDES), len(levels), scene.height, scene.width))
        ssim = np.ones((len(PAPER_SLIDES), len(levels)))
        for i, (a, f) in enumerate(PAPER_SLIDES):
            if progress:
                progress(f"bench lod-grid: the paper's slide amplitude {a:g}, frequency {f:g}")
            masks = []
            for j, (_, model) in enumerate(models):
                grid_images[i, j], mask = render_level_image(scene, model, a, f, None, supersample)
                masks.append(mask)
                if j:
                    from softshadow import masked_ssim
                    from softshadow.internal import comparison_region
                    ssim[i, j] = masked_ssim(grid_images[i, 0], grid_images[i, j],
                                             comparison_region(masks[0], mask))
        grid_seconds = (time.perf_counter() - t0) / (len(PAPER_SLIDES) * len(levels))
        table = measure_masking_table(scene, models, TABLE_AMPLITUDES, frequencies, (), supersample,
                                      progress=progress)
    faces = [lv.faces for lv in levels]
    choices = [_check(table, a, f, None, ssim[i]) for i, (a, f) in enumerate(PAPER_SLIDES)]
    result = {"faces": faces, "watertight": [lv.watertight for lv in levels],
              "slides": [{"amplitude": a, "frequency": f} for a, f in PAPER_SLIDES],
              "ssim": np.round(ssim, 4).tolist(), "hidden_threshold": HIDDEN_SSIM,
              "hidden": (ssim >= HIDDEN_SSIM).tolist(), "image_size": [scene.width, scene.height],
              "supersample": supersample, "seconds_per_image": round(grid_seconds, 3),
              "table": table.to_json(), "choices": choices,
              "check": {"slides": len(choices), "hidden": sum(c["measured_hidden"] for c in choices),
                        "coarsest": sum(c["coarsest"] for c in choices)},
              "date_utc": datetime.datetime.now(datetime.UTC).strftime("%Y-%m-%d %H:%M UTC")}
    if report_path:
        sunny = MaskingScene(width=scene.width, height=scene.height)
        with one_blas_thread():
            sun_table = measure_masking_table(sunny, models, TABLE_AMPLITUDES, frequencies, SUN_RANGES_K,
                                              supersample, progress=progress)
            sun_checks = []
            for k in SUN_CHECK_K:
                for a, f in PAPER_SLIDES:
                    if progress:
                        progress(f"bench lod-grid: sun k {k:g}, slide amplitude {a:g}, frequency {f:g}")
                    measured = _measure_slide(sunny, models, a, f, k, supersample)
                    sun_checks.append({"range_k": k, **_check(sun_table, a, f, k, measured)})
        result["sun"] = {"scene": sunny.sun_description(), "table": sun_table.to_json(), "checks": sun_checks,
                         "check": {"cases": len(sun_checks), "hidden": sum(c["measured_hidden"] for c in sun_checks),
                                   "coarsest": sum(c["coarsest"] for c in sun_checks)}}
        report = Path(report_path)
        report.parent.mkdir(parents=True, exist_ok=True)
        img = report.parent / "img" / "lod_grid.png"
        _draw_grid(grid_images, result, list(range(len(levels))), img)
        gif = report.parent / "img" / "lod_animation.gif"
        with one_blas_thread():
            result["animation"] = _animation([(scene, table), (sunny, sun_table)], models, gif, progress)
        report.write_text(masking_report(result, environment(), f"img/{img.name}", f"img/{gif.name}"))
        result["report"], result["image"], result["animation"]["path"] = str(report), str(img), str(gif)
    return result


def _without_sun(scene):
    import dataclasses
    return dataclasses.replace(scene, sun_irradiance=0.0)


def _measure_slide(scene, models, amplitude, frequency, range_k, supersample) -> np.ndarray:
    """SSIM (L,) of every level against the full mesh under one slide and sun."""
    from softshadow import masked_ssim
    from softshadow.internal import comparison_region, render_level_image
    full, full_mask = render_level_image(scene, models[0][1], amplitude, frequency, range_k, supersample)
    out = np.ones(len(models))
    for j, (_, model) in enumerate(models[1:], start=1):
        img, mask = render_level_image(scene, model, amplitude, frequency, range_k, supersample)
        out[j] = masked_ssim(full, img, comparison_region(full_mask, mask))
    return out


def _check(table, amplitude, frequency, range_k, measured: np.ndarray) -> dict:
    """The table's choice for these lights against the measured SSIM (L,) of every level."""
    choice = table.choose(amplitude, frequency, range_k)
    hidden = np.flatnonzero(np.asarray(measured) >= table.threshold)
    coarsest = int(hidden.max())
    return {"amplitude": amplitude, "frequency": frequency, "chosen_faces": table.faces[choice],
            "predicted_ssim": round(float(table.predict(amplitude, frequency, range_k)[choice]), 4),
            "measured_ssim": round(float(measured[choice]), 4),
            "measured_hidden": bool(measured[choice] >= table.threshold),
            "coarsest_hidden_faces": table.faces[coarsest], "coarsest": choice == coarsest}


def _animation(parts, models, path: Path, progress=None, frames: int = 32) -> dict:
    """A GIF: for each (scene, table) of ``parts``, ``frames`` frames with the slide's frequency
    rising 0 -> 30 and back and its amplitude swinging (and, with a sun, its k), each frame drawn
    (``FrameRenderer``, one sample per pixel) with the level the table chooses, its face count and
    the lights printed on it."""
    import imageio.v2 as imageio
    from PIL import Image, ImageDraw

    from softshadow import FrameRenderer, Pose, linear_to_srgb
    renderer = FrameRenderer()
    by_faces = dict(models)
    shown, milliseconds, images = [], [], []
    try:
        for scene, table in parts:
            sun = scene.sun_at()
            for i in range(frames):
                phase = i / frames
                frequency = 30.0 * (0.5 - 0.5 * np.cos(2 * np.pi * phase))
                amplitude = 0.6 + 0.4 * np.cos(2 * np.pi * 2 * phase)
                range_k = float(np.exp(np.log(0.003) + (np.log(0.03) - np.log(0.003)) * (0.5 - 0.5 * np.cos(
                    2 * np.pi * 3 * phase)))) if sun is not None else None
                if progress:
                    progress(f"bench lod-grid: animation frame {len(images) + 1}/{frames * len(parts)}")
                t = time.perf_counter()
                faces = table.faces[table.choose(amplitude, frequency, range_k)]
                frame = renderer.render(scene.camera(), by_faces[faces], Pose(), scene.lights(range_k or 0.01), sun,
                                        [scene.projector(amplitude, frequency)], object_albedo=scene.albedo,
                                        ground_albedo=scene.albedo)
                milliseconds.append(1e3 * (time.perf_counter() - t))
                rgb = (np.asarray(linear_to_srgb(np.clip(frame.image * _EXPOSURE, 0, 1))) * 255).astype(np.uint8)
                picture = Image.fromarray(rgb)
                draw = ImageDraw.Draw(picture)
                draw.text((8, 8), f"{faces:,} faces", fill=(255, 255, 0))
                draw.text((8, 22), f"slide: amplitude {amplitude:.2f}, frequency {frequency:.1f}", fill=(255, 255, 0))
                draw.text((8, 36), "no sun" if sun is None else f"sun: k {range_k:.4f}", fill=(255, 255, 0))
                images.append(np.asarray(picture.resize((scene.width // 2, scene.height // 2))))
                shown.append(faces)
    finally:
        renderer.close()
    path.parent.mkdir(parents=True, exist_ok=True)
    imageio.mimsave(path, images, duration=0.15, loop=0)
    return {"frames": len(images), "faces_shown": shown, "levels_used": sorted(set(shown), reverse=True),
            "frame_ms_median": round(float(np.median(milliseconds)), 1)}


def _draw_grid(images: np.ndarray, result: dict, columns: list[int], path: Path) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from softshadow import linear_to_srgb
    rows, cols = images.shape[:2]
    h, w = images.shape[2:4]
    fig, axes = plt.subplots(rows, cols, figsize=(2.6 * cols, 2.6 * rows * h / w + 0.5), squeeze=False)
    for i in range(rows):
        for jc, j in enumerate(columns):
            ax = axes[i, jc]
            ax.imshow(np.asarray(linear_to_srgb(np.clip(images[i, jc] * _EXPOSURE, 0.0, 1.0))), cmap="gray",
                      vmin=0, vmax=1)
            ax.set_xticks([])
            ax.set_yticks([])
            if j:
                ssim = result["ssim"][i][j]
                ax.text(0.03, 0.04, f"SSIM {ssim:.3f}" + (" hidden" if ssim >= result["hidden_threshold"] else ""),
                        transform=ax.transAxes, color="yellow", fontsize=7)
            if result["choices"][i]["chosen_faces"] == result["faces"][j]:
                for side in ax.spines.values():
                    side.set_edgecolor("yellow")
                    side.set_linewidth(2.5)
            if i == 0:
                ax.set_title(f"{result['faces'][j]:,} triangles", fontsize=9)
            if jc == 0:
                s = result["slides"][i]
                ax.set_ylabel(f"amplitude {s['amplitude']:g}\nfrequency {s['frequency']:g}", fontsize=8)
    fig.tight_layout(pad=0.3)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)


def masking_report(result: dict, env: dict, image: str, animation: str | None = None) -> str:
    """The Markdown report of ``lod_grid``'s JSON: the grid, the SSIM table, which slide hides
    which level, the table's choice against the measurements and, with the sun, its check."""
    faces = result["faces"]
    thr = result["hidden_threshold"]
    table = result["table"]
    lines = ["# Which slide hides which level of detail, and the level the masking chooses",
             "", "Made by `softshadow bench --what lod-grid --report docs/lod_masking.md` (the image is "
             f"`docs/{image}`); see [level_of_detail.md](level_of_detail.md) for the set-up.", "",
             f"![grid]({image})", "",
             f"Run {result['date_utc']} on a shared {env['machine']['cores']}-core {env['machine']['cpu']}, "
             f"load {env['machine']['load_average_1_5_15_min']} (1, 5, 15 min); images {result['image_size'][0]} "
             f"x {result['image_size'][1]} ({result.get('supersample', 1)} x {result.get('supersample', 1)} samples "
             f"per pixel, `render_frame`), {result['seconds_per_image']:.2f} s per image with its SSIM.", "",
             "## The paper's grid, measured", "",
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
    lines += ["", "## The level the masking chooses", "",
              "The masking table (`softshadow.MaskingTable`): the same SSIM measured once for this view on a grid "
              f"of other slides, amplitudes {', '.join(f'{a:g}' for a in table['amplitudes'])} and frequencies "
              f"{', '.join(f'{f:g}' for f in table['frequencies'])} (of the paper's slides only the spotlight, "
              "frequency 0, is on it), interpolated for any slide (linear in amplitude and in log(1 + "
              "frequency)): no level is rendered to choose. The choice is the coarsest level whose predicted "
              f"SSIM less the table's margin ({table['margin']:.3f}: the most its interpolation overestimated a "
              f"left-out grid value near the threshold) reaches {thr}.", "",
              "| slide (amplitude, frequency) | chosen | predicted SSIM | measured SSIM | coarsest hidden (measured) |",
              "|---|---:|---:|---:|---:|"]
    for c in result["choices"]:
        lines.append(f"| {c['amplitude']:g}, {c['frequency']:g} | {c['chosen_faces']:,} | {c['predicted_ssim']:.3f} | "
                     f"{c['measured_ssim']:.3f}{'' if c['measured_hidden'] else ' (not hidden)'} | "
                     f"{c['coarsest_hidden_faces']:,}{' (chosen)' if c['coarsest'] else ''} |")
    check = result["check"]
    lines += ["", f"Of the paper's {check['slides']} slides the chosen level is hidden (measured) under "
                  f"{check['hidden']} and is the coarsest hidden level under {check['coarsest']}."]
    if "sun" in result:
        sun = result["sun"]
        st = sun["table"]
        lines += ["", "## With the sun", "",
                  f"The same view with the sun ({sun['scene']}; its soft shadow the renderer's expanded shadow "
                  "volume): the comparison also covers the sun's shadow on the ground, whose outline a coarse "
                  "mesh changes and a wide penumbra blurs. The table adds the sun's k, "
                  f"{', '.join(f'{k:g}' for k in st['ranges_k'])} (margin {st['margin']:.3f}); checked at k between "
                  "those, under the paper's slides:", "",
                  "| k | slide | chosen | predicted SSIM | measured SSIM | coarsest hidden (measured) |",
                  "|---:|---|---:|---:|---:|---:|"]
        for c in sun["checks"]:
            lines.append(f"| {c['range_k']:g} | {c['amplitude']:g}, {c['frequency']:g} | {c['chosen_faces']:,} | "
                         f"{c['predicted_ssim']:.3f} | {c['measured_ssim']:.3f}"
                         f"{'' if c['measured_hidden'] else ' (not hidden)'} | {c['coarsest_hidden_faces']:,}"
                         f"{' (chosen)' if c['coarsest'] else ''} |")
        sc = sun["check"]
        lines += ["", f"Of these {sc['cases']} cases the chosen level is hidden (measured) in {sc['hidden']} and is "
                      f"the coarsest hidden level in {sc['coarsest']}."]
    if animation and "animation" in result:
        an = result["animation"]
        lines += ["", "## The level changing with the lights", "", f"![animation]({animation})", "",
                  f"{an['frames']} frames (`FrameRenderer`, 640 x 480, one sample per pixel, shown at half size): "
                  "the paper's scene, then the same with the sun; the slide's frequency and amplitude change (and "
                  "the sun's k), and each frame is drawn with the level its table chooses; levels used: "
                  f"{', '.join(f'{f:,}' for f in an['levels_used'])} faces; {an['frame_ms_median']:.0f} ms per "
                  "frame (median, the choice included)."]
    return "\n".join(lines) + "\n"
