"""``softshadow synth OUT_DIR --preset NAME --seed N``: a synthetic photo folder with its truth."""

from __future__ import annotations

import argparse
import sys

__all__ = ["add_arguments", "run", "parse_size"]


def parse_size(text: str) -> tuple[int, int]:
    """'1600x1200' -> (1600, 1200)."""
    from .validate import whole_pair
    try:
        w, h = whole_pair(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"size must look like 1600x1200, got {text!r}") from None
    if w < 16 or h < 16:
        raise argparse.ArgumentTypeError(f"size must be at least 16x16, got {text!r}")
    return w, h


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Add the synth options to an argparse (sub)parser."""
    from data_synth import FORMATS, PRESETS, RENDERERS

    parser.add_argument("out_dir", metavar="OUT_DIR", help="folder to write (images, scene.toml, truth.json)")
    parser.add_argument("--preset", default="table2", choices=PRESETS, help="scene preset (default table2)")
    parser.add_argument("--seed", type=int, default=0, help="random seed (default 0)")
    parser.add_argument("--renderer", default="physical", choices=RENDERERS,
                        help="physical (ray-cast sun disk + sky, default) or model (the project's own model)")
    parser.add_argument("--size", type=parse_size, default=None, metavar="WxH",
                        help="image size, e.g. 1600x1200 (the preset's default otherwise)")
    parser.add_argument("--format", dest="fmt", default=None, choices=FORMATS,
                        help="jpg (sRGB + EXIF, default), tiff/png (16-bit linear) or dng (needs pidng)")
    parser.add_argument("--quality", type=int, default=92, help="JPEG quality 1-100 (default 92)")
    parser.add_argument("--force", action="store_true", help="write into a non-empty OUT_DIR")
    parser.add_argument("--write-sun", dest="write_sun", action="store_true", default=None,
                        help="write each photo's sun into scene.toml (table2 leaves it to time + site)")
    parser.add_argument("--cameras", default="explicit", choices=("explicit", "markers"),
                        help="explicit: K, R, t per photo (default); markers: rely on the printed board")
    parser.add_argument("--no-progress", dest="progress", action="store_false", help="no progress bar")


def run(args: argparse.Namespace) -> int:
    """Run a synthesis from parsed arguments; 0 on success, 1 with a one-line reason on stderr."""
    from data_synth import OutputExistsError, synthesize

    try:
        out = synthesize(args.out_dir, preset=args.preset, seed=args.seed, renderer=args.renderer, size=args.size,
                         fmt=args.fmt, quality=args.quality, progress=getattr(args, "progress", True),
                         force=args.force, write_sun=getattr(args, "write_sun", None),
                         cameras=getattr(args, "cameras", "explicit"))
    except OutputExistsError as exc:
        print(f"softshadow synth: {exc}", file=sys.stderr)
        return 1
    except (ValueError, RuntimeError, OSError) as exc:
        print(f"softshadow synth: {exc}", file=sys.stderr)
        return 1
    if getattr(args, "cameras", "explicit") == "markers":
        warning = markers_warning(out)
        if warning:
            print(f"softshadow synth: warning: {warning}", file=sys.stderr)
    print(out)
    return 0


def markers_warning(folder) -> str | None:
    """One line when the printed board of a ``--cameras markers`` folder cannot be registered in
    some photos (the board is too small in the image at that size), else None. Each photo is
    registered as ``softshadow fit`` would."""
    from pathlib import Path

    from fitting import RegistrationError, list_photos, read_photo, register_board
    from scene import load_scene

    folder = Path(folder)
    scene = load_scene(folder / "scene.toml")
    files, _ = list_photos(folder)
    failed = []
    for f in files:
        spec = scene.camera_for(f.name)
        if spec is None or spec.kind != "markers":
            continue
        photo = read_photo(f)
        try:
            register_board(photo.gray, spec, exif=photo.exif)
        except RegistrationError as exc:
            failed.append((f.name, str(exc)))
    if not failed:
        return None
    name, reason = failed[0]
    return (f"the board cannot be registered in {len(failed)} of {len(files)} photos ({name}: {reason}); "
            "it is too small in the image at this size: use a larger --size (1600x1200 or more) or "
            "--cameras explicit")

