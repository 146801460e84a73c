"""Level of detail chosen by the projected light: an animation of the dragon under a changing slide.

    python examples/projector_lod.py [--table docs/lod_masking.json] [--out lod.gif] [--frames 40]

The masking table that ``softshadow bench --what lod-grid`` measured for the Dowling paper's view
(``docs/lod_masking.json``: the SSIM of each level of detail of the real dragon against the full
mesh on a grid of slides) predicts, for every frame's slide, the coarsest level the slide hides
(``MaskingTable.choose``: no level is rendered to choose); the frame is drawn with it
(``FrameRenderer``) and the level written on it. Run from a checkout (the dragon is vendored in
``benchmarks/data``).
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

import softshadow as ss


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    root = Path(__file__).resolve().parents[1]
    ap.add_argument("--table", default=str(root / "docs" / "lod_masking.json"))
    ap.add_argument("--out", default="lod.gif")
    ap.add_argument("--frames", type=int, default=40)
    args = ap.parse_args()
    import sys
    sys.path.insert(0, str(root))
    import imageio.v2 as imageio
    from PIL import Image, ImageDraw

    from benchmarks.meshes import mit_dragon
    table = ss.MaskingTable.from_json(json.loads(Path(args.table).read_text())["lod_grid"]["table"])
    mesh = mit_dragon(full=True)
    models = {lv.faces: ss.SoftShadowModel.from_mesh(lv.mesh) for lv in ss.lod_series(mesh, table.faces)}
    scene = ss.MaskingScene(sun_irradiance=0.0)  # the paper's set-up: the projector and ambient light
    renderer = ss.FrameRenderer()
    images = []
    try:
        with ss.one_blas_thread():
            for i in range(args.frames):
                phase = i / args.frames
                frequency = 30.0 * (0.5 - 0.5 * np.cos(2 * np.pi * phase))
                amplitude = 0.6 + 0.4 * np.cos(4 * np.pi * phase)
                faces = table.faces[table.choose(amplitude, frequency)]
                model = models[min(models, key=lambda f: abs(f - faces))]
                frame = renderer.render(scene.camera(), model, ss.Pose(), scene.lights(), None,
                                        [scene.projector(amplitude, frequency)], object_albedo=scene.albedo,
                                        ground_albedo=scene.albedo)
                rgb = (np.asarray(ss.linear_to_srgb(np.clip(0.9 * frame.image, 0, 1))) * 255).astype(np.uint8)
                picture = Image.fromarray(rgb)
                ImageDraw.Draw(picture).text((8, 8), f"{faces:,} faces  (slide {amplitude:.2f}, {frequency:.1f})",
                                             fill=(255, 255, 0))
                images.append(np.asarray(picture))
    finally:
        renderer.close()
    imageio.mimsave(args.out, images, duration=0.12, loop=0)
    print(f"wrote {args.out}: {len(images)} frames")


if __name__ == "__main__":
    main()
