"""``softshadow bench``: speed against error, printed as JSON (renderer and fitter)."""

from __future__ import annotations

import json

__all__ = ["run_bench"]


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
    if args.what in ("fit", "all"):
        from .fit import bench_fit
        result["fit"] = bench_fit(quick=args.quick)
    text = json.dumps(result, indent=1)
    print(text)
    if args.json_path:
        with open(args.json_path, "w") as f:
            f.write(text + "\n")
    return 0
