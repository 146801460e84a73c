"""``softshadow bench``: speed against error (renderer and fitter), as tables, and as JSON with ``--json``."""

from __future__ import annotations

import json
import sys
from pathlib import Path

__all__ = ["run_bench", "sweep_and_report", "overview_and_report"]


def _progress(msg: str) -> None:
    print(msg, file=sys.stderr, flush=True)


def _emit(result: dict, json_path) -> None:
    """Tables on stdout; the JSON document to ``json_path`` ("-": stdout instead of the tables)."""
    from .output import format_tables
    text = json.dumps(result, indent=1)
    if json_path == "-":
        print(text)
        return
    if json_path:
        Path(json_path).parent.mkdir(parents=True, exist_ok=True)
        Path(json_path).write_text(text + "\n")
    print(format_tables(result))


def sweep_and_report(settings, result: dict | None = None, fit: bool = True, json_path=None,
                     report_path=None, progress=_progress) -> dict:
    """The speed-against-error sweep in one run (``sweep.run_sweep``): its JSON (top-level keys
    per mesh, ``paper``, the peers, each timed case with its ``error``), with the date, machine,
    load (at the start and the end) and versions, written to ``json_path``; and the report made
    from that JSON alone, written to ``report_path`` (its plots in ``img/`` beside it)."""
    from .speed_report import write_report
    from .sweep import run_sweep
    return _run_and_report(lambda: run_sweep(settings, fit=fit, progress=progress), write_report, result,
                           json_path, report_path)


def overview_and_report(settings, result: dict | None = None, json_path=None, report_path=None,
                        progress=_progress) -> dict:
    """The plain ``softshadow bench`` (``overview.run_overview``: keys ``pillar``, ``ball``,
    ``dragon``, ``paper``, ``naive``, ``mitsuba``, ``summary``, each timed case with its
    ``error``), with the environment as ``sweep_and_report``; its short report to ``report_path``."""
    from .overview import run_overview
    from .speed_report import write_overview_report
    return _run_and_report(lambda: run_overview(settings, progress=progress), write_overview_report, result,
                           json_path, report_path)


def _run_and_report(run, write, result, json_path, report_path) -> dict:
    import datetime
    import time
    from .environment import environment, load_average
    t0 = time.perf_counter()
    result = {"environment": environment(), **(result or {})}
    result.update(run())
    result["environment"]["load_average_at_end"] = load_average()
    result["environment"]["run_minutes"] = round((time.perf_counter() - t0) / 60.0, 1)
    result["environment"]["finished_utc"] = datetime.datetime.now(datetime.UTC).strftime(
        "%Y-%m-%d %H:%M UTC")
    if json_path and json_path != "-":
        Path(json_path).parent.mkdir(parents=True, exist_ok=True)
        Path(json_path).write_text(json.dumps(result, indent=1) + "\n")
    if report_path:
        write(json.loads(json.dumps(result)), Path(report_path),
              Path(json_path).name if json_path and json_path != "-" else None)
    return result


def run_bench(args) -> int:
    """Run the bench ``args.what`` with a progress line on stderr; tables on stdout, JSON with --json."""
    if args.what == "coverage":
        return _run_coverage(args)
    from .output import StepProgress
    progress = StepProgress()
    try:
        return _run_bench(args, progress)
    finally:
        progress.close()


def _run_coverage(args) -> int:
    """The calibration study: a line per group on stderr (each one matters afterwards), the summary
    and the tables per factor bin on stdout; the whole JSON with --json (``-``: on stdout instead)."""
    from .coverage import coverage_and_report
    from .output import format_tables
    to_stdout = args.json_path == "-"
    if to_stdout:
        args.json_path = None
    result = coverage_and_report(args, progress=_progress)
    if to_stdout:
        print(json.dumps(result, indent=1))
    else:
        print(format_tables({"summary": [result["summary"]], "criteria": [result["criteria"]],
                             **{f"bins: {k}": v for k, v in result["bins"].items()}}))
    return 0


def _run_bench(args, progress) -> int:
    import jax
    import jax.numpy as jnp
    dtype = str(jnp.result_type(float))
    result = {"jax": jax.__version__, "devices": [str(d) for d in jax.devices()], "dtype": dtype,
              "settings": f"top-down map, k=0.01, rho=0.3, sun az 200 el 40, {dtype}"}
    if args.what == "overview":
        from .overview import overview_settings
        result = overview_and_report(overview_settings(quick=args.quick), result, json_path=args.json_path,
                                     report_path=getattr(args, "report", None), progress=progress)
        _emit(result, "-" if args.json_path == "-" else None)
        return 0
    if args.what == "sweep":
        from .scenes import SweepSettings
        result = sweep_and_report(SweepSettings(quick=args.quick), result, fit=getattr(args, "fit", True),
                                  json_path=args.json_path, report_path=getattr(args, "report", None), progress=progress)
        _emit(result, "-" if args.json_path == "-" else None)
        return 0
    if args.what == "scene":
        from .environment import environment, load_average
        from .scene import bench_scene
        result = {"environment": environment(), **result, **bench_scene(quick=args.quick, progress=progress)}
        result["environment"]["load_average_at_end"] = load_average()
        for warning in result["summary"]["warnings"]:
            print(f"bench scene: {warning}", file=sys.stderr)
        _emit(result, args.json_path)
        return 0
    if args.what in ("lod", "lod-grid"):
        from .environment import environment
        result = {"environment": environment(), **result}
        if args.what == "lod":
            from .lod import bench_lod
            result["lod"] = bench_lod(quick=args.quick, progress=progress)
        else:
            from .lod_grid import lod_grid
            result["lod_grid"] = lod_grid(quick=args.quick, report_path=getattr(args, "report", None),
                                          progress=progress)
        _emit(result, args.json_path)
        return 0
    sizes = (256, 512) if args.quick else (256, 512, 1024)
    if args.what in ("render", "all"):
        from .render import bench_render
        result["render"] = bench_render(sizes=sizes, repeats=3 if args.quick else 7)
    if args.what in ("render", "all", "receiver"):
        from .render import bench_depth_receiver
        result.setdefault("render", {})["depth_receiver_512"] = bench_depth_receiver(
            repeats=5 if args.quick else 15)
    if args.what in ("precision", "all"):
        from .shadow_precision import bench_shadow_precision
        result["shadow_map_precision"] = bench_shadow_precision()
    if args.what in ("fit", "all"):
        from .fit import bench_fit
        result["fit"] = bench_fit(quick=args.quick)
    if args.what == "startup":
        from .startup import bench_startup, write_startup_report
        result = _run_and_report(lambda: {"startup": bench_startup(quick=args.quick, progress=progress)},
                                 write_startup_report, result, args.json_path, getattr(args, "report", None))
    if args.what == "dragon-fit":
        from .dragon_fit import bench_dragon_fit
        from .environment import environment, load_average
        result = {"environment": environment(), **result}
        result["dragon_fit"] = bench_dragon_fit(quick=args.quick, progress=progress)
        result["environment"]["load_average_at_end"] = load_average()
    if args.what == "floor":
        from .floor import bench_floor
        result["floor"] = bench_floor(quick=args.quick, progress=progress)
    _emit(result, args.json_path)
    return 0
