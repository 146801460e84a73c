"""The ``softshadow`` command: render, fit, synth, demo, board, bench."""

from __future__ import annotations

import argparse
import os
import sys

__all__ = ["build_parser", "main"]

DESCRIPTION = """Measure outdoor soft shadows from photographs: the range k and the brightness rho of the
expanded-shadow-volume soft shadow (Shoji, Murayama and Konno), per time of day."""
EPILOG = """Start with `softshadow demo`; fit your own photos with `softshadow fit PHOTO_DIR --out OUT`.
Each command has its own --help. Documentation: the docs/ folder of the source (mkdocs serve)."""


class _HelpFormatter(argparse.RawDescriptionHelpFormatter):
    """Help with each option's default, where it has one and the help does not already say it."""

    def _get_help_string(self, action):
        text = action.help or ""
        if ("default" in text or action.default in (None, False, argparse.SUPPRESS)
                or action.option_strings == [] or isinstance(action.default, bool)):
            return text
        return f"{text} (default: %(default)s)"


def _parser(sub, name: str, **kwargs):
    return sub.add_parser(name, formatter_class=_HelpFormatter, **kwargs)


def _use_compilation_cache() -> None:
    """JAX's persistent compilation cache: a second run skips most compilation."""
    from softshadow import use_compilation_cache
    use_compilation_cache()


def _fail(command: str, message: str, code: int = 1) -> int:
    print(f"softshadow {command}: {message}" if command else f"softshadow: {message}", file=sys.stderr)
    return code


# -- render -----------------------------------------------------------------------------------
def _add_render(sub):
    p = _parser(sub, "render", help="render the model's soft shadow for a scene.toml to a PNG",
                       description="Render the expanded-shadow-volume soft shadow of a scene.")
    p.add_argument("--scene", required=True, help="scene.toml (object, camera, sun or time + site)")
    p.add_argument("--out", required=True, help="output PNG (8-bit sRGB)")
    p.add_argument("--photo", help="which [photos] entry's camera and sun to use (default: the first)")
    p.add_argument("--range", dest="range_paper", type=float, help="range in paper units (100 k)")
    p.add_argument("--brightness", type=float, help="brightness in paper units (255 rho^(1/2.2))")
    p.add_argument("--k", type=float, help="range as k (overrides --range); default 0.01")
    p.add_argument("--rho", type=float, help="brightness as rho (overrides --brightness); default 0.3")
    p.add_argument("--sun-azimuth", type=float, help="degrees clockwise from north")
    p.add_argument("--sun-elevation", type=float, help="degrees above the horizon")
    p.add_argument("--rule", default="edge", choices=("edge", "paper"),
                   help="how the silhouette expands: edge (each edge along its outward normal, so k is a "
                        "property of the light) or paper (the paper's vertex normals N1 + N2)")
    p.add_argument("--profile", default="linear", choices=("linear", "disk"),
                   help="the penumbra's profile: linear (the paper's ramp) or disk (the sun's disk behind a "
                        "straight edge)")
    p.add_argument("--size", help="image size WxH (default: 512x512 for a top-down map, the principal "
                                   "point's image for an explicit camera)")
    p.add_argument("--pixel-m", type=float, help="metres per pixel for a default top-down map")
    p.add_argument("--npy", help="also write the linear shading (H, W) as .npy ((H, W, 3) linear radiance for a "
                                 "scene image)")
    p.add_argument("--silhouettes", action="store_true",
                   help="draw the outer (expanded), hard and inner (contracted) outlines")
    g = p.add_argument_group("projectors and scene images",
                             "With a projector (here or [[projector]] in scene.toml) or --camera-position, render "
                             "a camera image of the whole scene: object and receivers, Lambertian, lit by an "
                             "ambient term (default rho), the sun (its soft shadow) and the projectors; see "
                             "docs/projector.md. Each projector option may be repeated, paired in order. Write "
                             "X,Y,Z values that start with a minus sign with =, e.g. --projector=-2,-3,3.")
    g.add_argument("--projector", action="append", metavar="X,Y,Z", help="a projector's position (metres)")
    g.add_argument("--projector-target", action="append", metavar="X,Y,Z", help="the point it looks at")
    g.add_argument("--projector-fov", action="append", type=float, metavar="DEG",
                   help="full angle across the slide's width (default 30)")
    g.add_argument("--slide", action="append", metavar="spot|sine:FREQ[:AMP]|PATH",
                   help="the slide: the spotlight, the spotlight through a sine grid of FREQ cycles across the "
                        "slide and amplitude AMP in [0, 1] (default 1), or an image file (default spot)")
    g.add_argument("--projector-intensity", action="append", type=float, metavar="E",
                   help="irradiance at the target through a clear slide, linear (default 1)")
    g.add_argument("--no-sun", action="store_true", help="no sun: ambient and projectors only (the paper's set-up)")
    g.add_argument("--ambient", type=float, help="ambient irradiance (default rho; 0.3 without the sun)")
    g.add_argument("--camera-position", metavar="X,Y,Z", help="a look-at camera's position (with --camera-target)")
    g.add_argument("--camera-target", metavar="X,Y,Z", help="the point the camera looks at")
    g.add_argument("--camera-fov", type=float, metavar="DEG", help="its horizontal field of view (default 50)")
    g.add_argument("--smooth", action="store_true",
                   help="interpolate vertex normals (default: flat faces, which show a mesh's facets)")
    g.add_argument("--supersample", type=int, default=1, metavar="S",
                   help="S x S samples per pixel, averaged (anti-aliasing; default 1)")
    g.add_argument("--exposure", type=float, default=1.0, help="scale the linear image before sRGB encoding "
                                                                "(default 1; values above 1 clip)")
    p.set_defaults(func=_run_render)


def _run_render(args) -> int:
    import numpy as np

    from .render_command import render_scene_file
    from .validate import OptionError
    try:
        image, shading = render_scene_file(args)
    except OptionError as exc:
        return _fail("render", str(exc).splitlines()[0], 2)
    except (ValueError, OSError) as exc:
        return _fail("render", str(exc).splitlines()[0])
    from PIL import Image
    try:
        Image.fromarray(image).save(args.out)
        if args.npy:
            np.save(args.npy, shading)
    except (ValueError, OSError) as exc:
        return _fail("render", f"cannot write the image: {exc}".splitlines()[0])
    print(f"wrote {args.out}" + (f" and {args.npy}" if args.npy else ""))
    return 0


# -- fit ----------------------------------------------------------------------------------------
def _add_fit(sub):
    p = _parser(sub, "fit", help="fit range and brightness per time of day from a photo folder",
                       description="Fit the soft shadow's range k and brightness rho per time of day.")
    p.add_argument("photo_dir", metavar="PHOTO_DIR", help="a photo folder (with --recursive: ROOT, a folder of them)")
    p.add_argument("--out", required=True, metavar="OUT_DIR", help="results.json, table2.md/.csv, plots/")
    p.add_argument("--recursive", action="store_true",
                   help="fit every photo folder under ROOT into OUT/<relative path>/ on Dask, with "
                        "OUT/summary.csv and OUT/summary.png; an interrupted run resumes")
    p.add_argument("--scheduler", default="local", metavar="local|tcp://HOST:PORT",
                   help="with --recursive: local worker processes (default) or an existing Dask "
                        "scheduler's address")
    p.add_argument("--workers", type=int, default=None, metavar="N",
                   help="with --recursive and --scheduler local: worker processes (default: one per core)")
    p.add_argument("--force", action="store_true", help="overwrite existing results and refit all groups")
    p.add_argument("--jobs", type=int, default=1, help="groups fitted at once (threads; default 1)")
    p.add_argument("--verbose", action="store_true", help="print solver details, and the traceback of an unexpected error")
    p.add_argument("--profile", default="disk", choices=("auto", "linear", "disk"),
                   help="penumbra profile: disk (the sun's, default: k reads tan(sun radius)), "
                        "linear (the paper's ramp), or auto (chosen by BIC)")
    p.add_argument("--rule", default="edge", choices=("edge", "paper", "wedge", "auto"),
                   help="the penumbra's rule: edge (a ramp about the nearest silhouette edge, along its outward "
                        "normal), paper (the paper's vertex normals), wedge (the sun's hidden fraction: right "
                        "where edges crowd, slower), or auto (edge, refitted with wedge per group where the two "
                        "differ by more than the photos' noise; the rule used is in results.json)")
    p.add_argument("--range-k-max", type=float, default=0.03, help="largest k searched (default 0.03)")
    p.add_argument("--half-size", action="store_true", help="read every photo at half its width and height (RAW decoded at half size, others shrunk): faster, for large photos")
    p.add_argument("--no-plots", dest="plots", action="store_false",
                   help="write results.json and the tables only (no plots, no index.html figures)")
    p.add_argument("--overlays", default=None, choices=("first", "all"),
                   help="overlay plots of the fitted shadow for the first photo of each group "
                        "(default) or for every photo")
    p.add_argument("--lod", default="auto", type=_lod_value, metavar="auto|off|FACES",
                   help="level of detail of the object's mesh: auto (default: the coarsest level that "
                        "moves k and rho by at most --lod-tolerance of their standard errors), off "
                        "(the mesh as given), or a face count to decimate to")
    p.add_argument("--lod-tolerance", type=float, default=None, metavar="SE",
                   help="with --lod auto: the largest shift of k or rho allowed, in their stated "
                        "standard errors, systematic part included (default 0.1)")
    p.set_defaults(func=_run_fit)


def _lod_value(text: str):
    """--lod: "auto", "off" or a face count (at least 4)."""
    if text in ("auto", "off"):
        return text
    try:
        faces = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected auto, off or a face count, got {text!r}") from None
    if faces < 4:
        raise argparse.ArgumentTypeError(f"a level of detail needs at least 4 faces, got {faces}")
    return faces


def _run_fit(args) -> int:
    from .fit_command import run_fit
    return run_fit(args)


# -- synth / demo / bench -----------------------------------------------------------------------
def _add_synth(sub, with_arguments: bool):
    p = _parser(sub, "synth", help="write a synthetic photo folder with known truth",
                       description="Synthesise a photo folder (images, scene.toml, truth.json).")
    from .synth_command import add_arguments, run
    if with_arguments:  # their choices come from data_synth, which loads trimesh and JAX (seconds)
        add_arguments(p)
    p.set_defaults(func=run)


def _add_demo(sub):
    p = _parser(sub, "demo", help="synthesise the paper's scene, fit it, print the table",
                       description="Synthesise the table2 preset (physical renderer), fit it and print "
                                   "the fitted table beside the truth and the paper's hand-set values.")
    p.add_argument("--out", default="softshadow-demo", help="where to write the photos and results")
    p.add_argument("--seed", type=int, default=0, help="random seed of the synthetic photos (noise, texture)")
    p.add_argument("--size", default="800x600", help="photo size (default 800x600)")
    p.set_defaults(func=_run_demo)


def _run_demo(args) -> int:
    from .demo_command import run_demo
    return run_demo(args)


def _add_board(sub):
    p = _parser(sub, "board", help="write the printable ChArUco board that registers your photos",
                description="Write a ChArUco board to print (PDF or PNG at its true size), and print the "
                            "scene.toml [camera] entry that registers photos of it.")
    from .board_command import add_arguments, run_board
    add_arguments(p)
    p.set_defaults(func=run_board)


def _add_bench(sub):
    p = _parser(
        sub, "bench", help="time the renderers and the fitter against a known truth (tables; JSON with --json)",
        description="Benchmarks (from a source checkout): speed against error, as tables (the JSON with --json). Without --what (overview, a minute or two on "
                    "2 cores): the pillar, the ball and the real dragon at 128x128, each rendered by this "
                    "renderer (keys pillar, ball, dragon), the Shoji paper's algorithm, hard and soft (paper), "
                    "the naive every-pixel-against-every-edge renderer (naive) and Mitsuba 3 at 4/16/64 spp "
                    "where installed (mitsuba; else 'skipped'), every timed case with its error (RMS over the "
                    "map and the penumbra band) against a converged physical render, cached on disk; "
                    "'summary' lists them with times as multiples of this renderer's. The full report: "
                    "--what sweep --json docs/speed_vs_error.json --report docs/speed_vs_error.md.")
    p.add_argument("--json", dest="json_path", metavar="FILE",
                   help="write the JSON document here (- : print it instead of the tables)")
    p.add_argument("--quick", action="store_true", help="fewer repeats and sizes")
    p.add_argument("--what", default="overview",
                   choices=("overview", "render", "fit", "all", "sweep", "receiver", "precision", "lod",
                            "lod-grid", "scene", "floor", "startup", "coverage", "dragon-fit"),
                   help="overview (the default, above); the renderer's and fitter's micro benchmarks without "
                        "errors: render / fit, or both (all); the full speed-against-error sweep with its "
                        "image and parameter errors against a known truth (sweep); the light-space back "
                        "end on a 512x512 range image beside the ground map (receiver, also in render); "
                        "the shadow map's depth in float32 against float64 (precision); the fit on the "
                        "real 41k-face dragon at each level of detail (lod); the Dowling paper's grid of "
                        "levels of detail under its slides with the SSIM masking table (lod-grid); the "
                        "scene image at 640x480 (the dragon and its levels, sun, projector, ambient) per "
                        "frame (scene); the "
                        "renderer's error floor against a physical render, before and after its pixel "
                        "footprint and hidden sky (floor); a fit in a fresh process through the command line "
                        "and through the Python API, alternated (startup); the randomized calibration study of "
                        "the stated errors: groups drawn from a documented prior, rendered by the physical "
                        "renderer, fitted and compared with their truth, hours of CPU for 300 groups, resumable "
                        "(coverage); fits of a physical folder of the real dragon at 41k, 5k and 1k faces "
                        "with the edge, wedge and auto penumbra rules, k's and rho's bias (dragon-fit)")
    p.add_argument("--report", help="with overview, sweep, lod-grid, startup or coverage: also write the Markdown "
                                    "report here (and its images in img/ beside it), e.g. docs/benchmarks.md, "
                                    "docs/speed_vs_error.md, docs/lod_masking.md, docs/startup.md, "
                                    "docs/uncertainty_study.md")
    p.add_argument("--groups", type=int, default=300, help="with coverage: how many groups to draw (default 300)")
    p.add_argument("--seed", type=int, default=0, help="with coverage: the study's seed (group i is drawn from "
                                                      "numpy's default_rng([seed, i]))")
    p.add_argument("--root", help="with coverage: where the groups' folders and records.jsonl go (default "
                                  "/tmp/softshadow-coverage-sSEED); a stopped run resumes from its records")
    p.add_argument("--only", help="with coverage: these groups only, e.g. 3,17,40-45")
    p.add_argument("--refit", action="store_true",
                   help="with coverage: fit the kept folders again (a changed verdict) instead of reusing records")
    p.add_argument("--from-json", dest="from_json",
                   help="with coverage: remake the tables and the report from this JSON, without fitting")
    p.add_argument("--no-fit", dest="fit", action="store_false",
                   help="with --what sweep: leave out the fits (images only)")
    p.set_defaults(func=_run_bench)


def _run_bench(args) -> int:
    from .checkout import import_benchmarks
    benchmarks = import_benchmarks()
    if benchmarks is None:
        return _fail("bench", "the benchmarks live in a source checkout, not in the installed package: "
                              "git clone the repository, pip install -e . there, and run softshadow bench from it", 2)
    return benchmarks.run_bench(args)


def build_parser(with_synth_arguments: bool = True) -> argparse.ArgumentParser:
    """The ``softshadow`` command's parser. The synth command's options come from data_synth, which
    loads trimesh and JAX (seconds): ``with_synth_arguments=False`` leaves them out."""
    parser = argparse.ArgumentParser(prog="softshadow", description=DESCRIPTION, epilog=EPILOG,
                                     formatter_class=_HelpFormatter)
    from softshadow import __version__
    parser.add_argument("--version", action="version", version=f"softshadow {__version__}")
    sub = parser.add_subparsers(dest="command", required=True)
    _add_render(sub)
    _add_fit(sub)
    _add_synth(sub, with_arguments=with_synth_arguments)
    _add_demo(sub)
    _add_board(sub)
    _add_bench(sub)
    return parser


def _option_problem(args) -> str | None:
    """One line on the first option of ``args`` that cannot be used (softshadow_cli.validate)."""
    from .validate import option_problem
    return option_problem(args)


def main(argv=None) -> int:
    """Run the ``softshadow`` command on ``argv`` (default: the process's arguments) and return
    its exit status (130 after Ctrl-C)."""
    code = _main(sys.argv[1:] if argv is None else list(argv))
    if code == 130:
        from .interrupts import quiet_after_interrupt
        quiet_after_interrupt()
    return code


def run(argv=None) -> None:
    """The ``softshadow`` executable: ``main``, then exit with its status. After Ctrl-C the process
    ends at once, with the command's files closed and its output flushed: a native thread the
    interruption left running (an XLA compilation) can crash the interpreter's shutdown."""
    code = main(argv)
    if code == 130:
        sys.stdout.flush()
        sys.stderr.flush()
        os._exit(130)
    sys.exit(code)


def _main(argv: list[str]) -> int:
    from .interrupts import ctrl_c_never_swallowed, ctrl_c_pressed
    # The command's name for a message before the arguments are parsed (a Ctrl-C during imports).
    command = next((a for a in argv if a in ("render", "fit", "synth", "demo", "board", "bench")), "")
    args = code = None
    try:
        # From the first import on: a Ctrl-C that lands inside an extension module's
        # initialisation (jaxlib) must not abort the process.
        with ctrl_c_never_swallowed():
            args = build_parser(with_synth_arguments="synth" in argv).parse_args(argv)
            problem = _option_problem(args)
            if problem:  # before any work
                return _fail(command, problem, 2)
            _use_compilation_cache()
            from softshadow import one_blas_thread
            with one_blas_thread():
                code = int(args.func(args) or 0)
        if ctrl_c_pressed() and code != 130:
            # A Ctrl-C a library swallowed, pressed too late to stop the work it was meant to stop.
            return _fail(command, "interrupted (the command had finished its work)", 130)
        return code
    except KeyboardInterrupt:
        if code == 130:  # delivered again while the command, interrupted, was ending: said already
            return 130
        if code is not None:
            return _fail(command, "interrupted (the command had finished its work)", 130)
        return _fail(command, "interrupted", 130)
    except Exception as exc:
        if ctrl_c_pressed():  # a library turned the KeyboardInterrupt into another exception
            return _fail(command, "interrupted", 130)
        # A bug or an unforeseen input: one line for the user, the traceback with --verbose.
        if getattr(args, "verbose", False):
            raise
        first = (str(exc).splitlines() or [""])[0]
        return _fail(command, f"unexpected error: {type(exc).__name__}: {first}"
                     + (" (--verbose shows the traceback)" if hasattr(args, "verbose") else ""))


if __name__ == "__main__":
    run()
