"""Every option of ``softshadow render`` and ``softshadow fit`` checked before any work.

Each check raises ``OptionError`` with one line naming the option, its value and the range it
must lie in; the command prints it and exits with status 2 (argparse's status for a bad
option), before anything is read, rendered, fitted or written.
"""

from __future__ import annotations

import math
from pathlib import Path

__all__ = ["OptionError", "option_problem", "parse_size", "check_render_options", "check_fit_options",
           "check_synth_options", "check_demo_options", "check_board_options", "check_bench_options",
           "check_output_file",
           "check_output_folder", "RENDER_MAX_SIDE", "RANGE_K_LIMIT"]

#: The largest width or height ``softshadow render --size`` draws (a larger image is a typo).
RENDER_MAX_SIDE = 16384
#: The largest range k an option takes: a penumbra as wide as the object is tall (45 degrees).
RANGE_K_LIMIT = 1.0


class OptionError(ValueError):
    """An option that cannot be used: one line naming it (exit status 2)."""


def option_problem(args) -> str | None:
    """The first option of a parsed command line that cannot be used (one line), or None."""
    check = {"render": check_render_options, "fit": check_fit_options, "synth": check_synth_options,
             "demo": check_demo_options, "board": check_board_options,
             "bench": check_bench_options}.get(getattr(args, "command", None))
    try:
        if check is not None:
            check(args)
    except OptionError as exc:
        return str(exc).splitlines()[0]
    return None


def _number(option: str, value, *, low: float | None = None, high: float | None = None,
            low_open: bool = False, high_open: bool = False, why: str = "") -> None:
    """A finite number in [low, high] (an end excluded when ``*_open``); None (not given) passes."""
    if value is None:
        return
    if not math.isfinite(value):
        raise OptionError(f"{option} must be a finite number, got {value:g}")
    below = low is not None and (value <= low if low_open else value < low)
    above = high is not None and (value >= high if high_open else value > high)
    if below or above:
        lo = "" if low is None else ("(" if low_open else "[") + f"{low:g}"
        hi = "" if high is None else f"{high:g}" + (")" if high_open else "]")
        if low is not None and high is not None:
            span = f"in {lo}, {hi}"
        elif low is not None:
            span = f"{'>' if low_open else '>='} {low:g}"
        else:
            span = f"{'<' if high_open else '<='} {high:g}"
        raise OptionError(f"{option} must be {span}, got {value:g}" + (f" ({why})" if why else ""))


def _whole(option: str, value, low: int, high: int | None = None, why: str = "") -> None:
    if value is None:
        return
    if value < low or (high is not None and value > high):
        span = f"at least {low}" if high is None else f"from {low} to {high}"
        raise OptionError(f"{option} must be {span}, got {value}" + (f" ({why})" if why else ""))


def whole_pair(text) -> tuple[int, int]:
    """'640x480' -> (640, 480); ValueError unless the text is two whole numbers joined by an x."""
    first, second = (int(v) for v in str(text).lower().split("x"))
    return first, second


def parse_size(text: str, option: str = "--size") -> tuple[int, int]:
    """'640x480' -> (640, 480): whole numbers from 1 to RENDER_MAX_SIDE."""
    try:
        w, h = whole_pair(text)
    except ValueError:
        raise OptionError(f"{option} must look like 640x480 (width x height in pixels), got {text!r}") from None
    for side in (w, h):
        if not 1 <= side <= RENDER_MAX_SIDE:
            raise OptionError(f"{option} must be from 1x1 to {RENDER_MAX_SIDE}x{RENDER_MAX_SIDE} pixels, "
                              f"got {text!r}")
    return w, h


def _xyz(option: str, text) -> None:
    try:
        values = [float(v) for v in str(text).split(",")]
    except ValueError:
        values = []
    if len(values) != 3 or not all(math.isfinite(v) for v in values):
        raise OptionError(f"{option} must be three numbers X,Y,Z (metres), got {text!r}")


def check_output_file(option: str, path, suffixes: tuple[str, ...] | None = None,
                      folder_made: bool = False) -> None:
    """An output file that can be written: its folder exists and is writable (or, with
    ``folder_made``, can be created: the command makes it), it is not a folder, and (with
    ``suffixes``) its extension is one of them."""
    import os
    path = Path(path)
    if path.is_dir():
        raise OptionError(f"{option} {path} is a folder; give a file name")
    if suffixes is not None and path.suffix.lower() not in suffixes:
        raise OptionError(f"{option} {path} must end in one of {', '.join(sorted(set(suffixes)))}")
    parent = path.parent if str(path.parent) else Path(".")
    if folder_made:
        check_output_folder(option, parent)
        return
    if not parent.exists():
        raise OptionError(f"{option} {path}: the folder {parent} does not exist")
    if not parent.is_dir():
        raise OptionError(f"{option} {path}: {parent} is a file, not a folder")
    if not os.access(parent, os.W_OK | os.X_OK):
        raise OptionError(f"{option} {path}: the folder {parent} cannot be written")


def check_output_folder(option: str, path) -> None:
    """A folder that can be created or written: not a file, not under a file, and its nearest
    existing parent writable. Creates nothing."""
    import os
    path = Path(path)
    label = f"{option} {path}" if option else str(path)
    if path.exists() and not path.is_dir():
        raise OptionError(f"{label} is a file, not a folder")
    probe = path
    while not probe.exists() and probe.parent != probe:
        probe = probe.parent
    if not probe.is_dir():
        raise OptionError(f"{label} cannot be created: {probe} is a file, not a folder")
    if not os.access(probe, os.W_OK | os.X_OK):
        raise OptionError(f"{label} cannot be written: {probe} is read-only")


def _image_suffixes() -> tuple[str, ...]:
    """File extensions Pillow can write."""
    from PIL import Image
    Image.init()
    return tuple(ext for ext, fmt in Image.registered_extensions().items() if fmt in Image.SAVE)


def check_render_options(args) -> None:
    """``softshadow render``'s options, before the scene is read (raises OptionError)."""
    _number("--k", args.k, low=0.0, high=RANGE_K_LIMIT,
            why="the range of the soft shadow; 0 is a hard shadow")
    _number("--range", args.range_paper, low=0.0, high=100 * RANGE_K_LIMIT,
            why="paper units, 100 k")
    _number("--rho", args.rho, low=0.0, high=1.0, low_open=True,
            why="the umbra's brightness as a fraction of the lit ground's")
    _number("--brightness", args.brightness, low=0.0, high=255.0, low_open=True,
            why="paper units, 255 rho^(1/2.2)")
    _number("--sun-azimuth", args.sun_azimuth, low=-360.0, high=360.0, why="degrees clockwise from north")
    _number("--sun-elevation", args.sun_elevation, low=0.0, high=90.0, low_open=True,
            why="degrees above the horizon: a sun at or below it casts no shadow")
    if args.size is not None:
        parse_size(args.size)
    _number("--pixel-m", args.pixel_m, low=0.0, low_open=True, why="metres per pixel")
    _number("--ambient", getattr(args, "ambient", None), low=0.0)
    _number("--exposure", getattr(args, "exposure", None), low=0.0, low_open=True)
    _whole("--supersample", getattr(args, "supersample", None), 1, 16, "samples per pixel: S x S")
    _number("--camera-fov", getattr(args, "camera_fov", None), low=0.0, high=180.0, low_open=True,
            high_open=True, why="degrees")
    for fov in getattr(args, "projector_fov", None) or []:
        _number("--projector-fov", fov, low=0.0, high=170.0, low_open=True, high_open=True, why="degrees")
    for level in getattr(args, "projector_intensity", None) or []:
        _number("--projector-intensity", level, low=0.0)
    for option, attr in (("--camera-position", "camera_position"), ("--camera-target", "camera_target")):
        if getattr(args, attr, None) is not None:
            _xyz(option, getattr(args, attr))
    if (getattr(args, "camera_position", None) is None) != (getattr(args, "camera_target", None) is None):
        raise OptionError("give both --camera-position and --camera-target")
    for option, attr in (("--projector", "projector"), ("--projector-target", "projector_target")):
        for text in getattr(args, attr, None) or []:
            _xyz(option, text)
    _check_projector_counts(args)
    check_output_file("--out", args.out, _image_suffixes())
    if args.npy:
        check_output_file("--npy", args.npy, (".npy",))
        if Path(args.npy).resolve() == Path(args.out).resolve():
            raise OptionError("--npy and --out name the same file")


def _check_projector_counts(args) -> None:
    """The projector options pair up in order: one target per --projector, and every other
    projector option given once (for all) or once per --projector."""
    n = len(getattr(args, "projector", None) or [])
    others = (("--projector-fov", "projector_fov"), ("--slide", "slide"),
              ("--projector-intensity", "projector_intensity"))
    if not n:
        for option, attr in (("--projector-target", "projector_target"),) + others:
            if getattr(args, attr, None):
                raise OptionError(f"{option} needs --projector X,Y,Z")
        return
    targets = len(getattr(args, "projector_target", None) or [])
    if targets != n:
        raise OptionError(f"give one --projector-target X,Y,Z per --projector ({n}), got {targets}")
    for option, attr in others:
        given = len(getattr(args, attr, None) or [])
        if given not in (0, 1, n):
            raise OptionError(f"give {option} once, or once per --projector ({n}), not {given} times")


def check_fit_options(args) -> None:
    """``softshadow fit``'s options, before the folder is read (raises OptionError). The output
    folder is checked separately (``fit_command.check_out_dir``)."""
    _number("--range-k-max", args.range_k_max, low=0.0, high=RANGE_K_LIMIT, low_open=True,
            why="the largest range k searched; the real sun gives 0.0047, haze up to about 0.01")
    _whole("--jobs", args.jobs, 1, 64, "groups fitted at once")
    _whole("--workers", getattr(args, "workers", None), 1, 1024, "worker processes")
    _number("--lod-tolerance", getattr(args, "lod_tolerance", None), low=0.0,
            why="standard errors")
    if getattr(args, "lod_tolerance", None) is not None and getattr(args, "lod", "auto") != "auto":
        raise OptionError(f"--lod-tolerance goes with --lod auto, not --lod {args.lod}")
    if getattr(args, "overlays", None) is not None and not args.plots:
        raise OptionError("--overlays chooses plots; it does not go with --no-plots")
    if not getattr(args, "recursive", False) and (
            getattr(args, "scheduler", "local") != "local" or getattr(args, "workers", None) is not None):
        raise OptionError("--scheduler and --workers go with --recursive")


def _seed(value) -> None:
    if value is not None and value < 0:
        raise OptionError(f"--seed must be a whole number >= 0, got {value}")


def check_synth_options(args) -> None:
    """``softshadow synth``'s options, before anything is rendered (raises OptionError)."""
    _seed(getattr(args, "seed", None))
    _whole("--quality", getattr(args, "quality", None), 1, 100, "JPEG quality")
    if getattr(args, "out_dir", None) is not None:
        check_output_folder("OUT_DIR", args.out_dir)


def check_demo_options(args) -> None:
    """``softshadow demo``'s options (raises OptionError)."""
    import argparse

    from .synth_command import parse_size as synth_size
    _seed(args.seed)
    try:
        synth_size(args.size)
    except argparse.ArgumentTypeError as exc:
        raise OptionError(f"--size: {exc}") from None
    check_output_folder("--out", args.out)


def check_bench_options(args) -> None:
    """``softshadow bench``'s output files, before minutes of benchmarks (raises OptionError)."""
    # The bench makes the folders of its JSON and its report (docs/ and docs/img/ of a fresh checkout).
    if getattr(args, "json_path", None) and args.json_path != "-":
        check_output_file("--json", args.json_path, folder_made=True)
    if getattr(args, "report", None):
        check_output_file("--report", args.report, folder_made=True)
    if getattr(args, "what", None) == "coverage":
        _number("--groups", getattr(args, "groups", None), low=1, why="groups to draw")
        source = getattr(args, "from_json", None)
        if source and not Path(source).is_file():
            raise OptionError(f"--from-json {source}: no such file")
        only = getattr(args, "only", None)
        if only and not all(p.strip().replace("-", "", 1).isdigit() for p in str(only).split(",")):
            raise OptionError(f"--only {only}: give group numbers and ranges, e.g. 3,17,40-45")


def check_board_options(args) -> None:
    """``softshadow board``'s numbers (its own checks cover the file and the board's layout)."""
    _number("--dpi", getattr(args, "dpi", None), low=10.0, high=2400.0, why="dots per inch of the page")
    _number("--square-mm", getattr(args, "square_mm", None), low=0.0, low_open=True, why="millimetres")
