"""Wall time of `softshadow fit` on one 4000x3000 photo without geometry, in a fresh process; print JSON.

Usage: python examples/bench_photo_speed.py [--photo PATH] [--size 4000x3000] [--repeat 2]

The photo is resized (Lanczos) to --size and written as a JPEG (quality 92)
into a temporary folder with no scene.toml; then `python -m softshadow_cli fit`
runs on it in a new process, so the figure includes Python start-up, imports,
decoding, the measurement and the report. Without --photo, a `street` preset
photo (seed 0, 1024x768, licence-free) is rendered and upscaled.

Reported: wall seconds per run, the child's user+system CPU seconds, the load
average before each run, the result (rho, reliable) and the machine's cores.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from PIL import Image


def _photo_folder(photo: str | None, size: tuple[int, int], root: Path) -> Path:
    folder = root / "photo"
    folder.mkdir()
    if photo is None:
        from data_synth import synthesize
        src = synthesize(root / "street", "street", seed=0, size=(1024, 768), progress=False)
        photo = str(next(src.glob("street_0.*")))
    with Image.open(photo) as im:
        im.convert("RGB").resize(size, Image.LANCZOS).save(folder / f"{Path(photo).stem}_{size[0]}x{size[1]}.jpg",
                                                           quality=92)
    return folder


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--photo", help="a photo to upscale (default: a rendered street photo)")
    ap.add_argument("--size", default="4000x3000")
    ap.add_argument("--repeat", type=int, default=2)
    args = ap.parse_args(argv)
    size = tuple(int(v) for v in args.size.lower().split("x"))
    runs = []
    with tempfile.TemporaryDirectory() as tmp:
        root = Path(tmp)
        folder = _photo_folder(args.photo, size, root)
        for r in range(args.repeat):
            out = root / f"out{r}"
            load = os.getloadavg()[0]
            before = resource.getrusage(resource.RUSAGE_CHILDREN)
            t0 = time.perf_counter()
            proc = subprocess.run([sys.executable, "-m", "softshadow_cli", "fit", str(folder), "--out", str(out)],
                                  capture_output=True, text=True)
            wall = time.perf_counter() - t0
            after = resource.getrusage(resource.RUSAGE_CHILDREN)
            if proc.returncode != 0:
                raise SystemExit(f"softshadow fit failed: {proc.stderr.strip().splitlines()[-1:]}")
            group = json.loads((out / "results.json").read_text())["groups"][0]
            runs.append({"wall_s": round(wall, 2),
                         "cpu_s": round(after.ru_utime - before.ru_utime + after.ru_stime - before.ru_stime, 2),
                         "load_before": round(load, 2), "rho": group.get("rho"), "reliable": group.get("reliable")})
    print(json.dumps({"size": list(size), "photo": args.photo or "street seed 0 (upscaled)", "cores": os.cpu_count(),
                      "runs": runs}, indent=1))


if __name__ == "__main__":
    main()
