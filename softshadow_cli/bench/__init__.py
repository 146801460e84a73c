"""``softshadow bench``: speed against error, printed as JSON (renderer and fitter)."""

from __future__ import annotations

import json
import sys
from pathlib import Path

__all__ = ["run_bench"]


def _sweep(args, result: dict) -> dict:
    """The speed-against-error sweep (top-level keys per mesh, each with its ``error``), and the
    report made from it when asked."""
    from .environment import environment
    from .sweep import SweepSettings, run_sweep
    result = {"environment": environment(), **result}
    result.update(run_sweep(SweepSettings(quick=args.quick), fit=getattr(args, "fit", True),
                            progress=lambda msg: print(msg, file=sys.stderr, flush=True)))
    if getattr(args, "report", None):
        from .speed_report import write_report
        write_report(result, Path(args.report), Path(args.json_path).name if args.json_path else None)
    return result


def run_bench(args) -> int:
    import jax
    import jax.numpy as jnp
    dtype = str(jnp.result_type(float))
    result = {"jax": jax.__version__, "devices": [str(d) for d in jax.devices()], "dtype": dtype,
              "settings": f"top-down map, k=0.01, rho=0.3, sun az 200 el 40, {dtype}"}
    sizes = (256, 512) if args.quick else (256, 512, 1024)
    if args.what in ("render", "all"):
        from .render import bench_render
        result["render"] = bench_render(sizes=sizes, repeats=3 if args.quick else 7)
    if args.what in ("render", "all", "receiver"):
        from .render import bench_depth_receiver
        result.setdefault("render", {})["depth_receiver_512"] = bench_depth_receiver(
            repeats=3 if args.quick else 7)
    if args.what in ("precision", "all"):
        from .shadow_precision import bench_shadow_precision
        result["shadow_map_precision"] = bench_shadow_precision()
    if args.what in ("fit", "all"):
        from .fit import bench_fit
        result["fit"] = bench_fit(quick=args.quick)
    if args.what == "floor":
        from .floor import bench_floor
        result["floor"] = bench_floor(quick=args.quick,
                                      progress=lambda msg: print(msg, file=sys.stderr, flush=True))
    if args.what == "sweep":
        result = _sweep(args, result)
    text = json.dumps(result, indent=1)
    print(text)
    if args.json_path:
        with open(args.json_path, "w") as f:
            f.write(text + "\n")
    return 0
