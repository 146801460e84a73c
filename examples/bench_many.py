"""Throughput of ``softshadow fit ROOT --recursive`` on Dask against a plain loop; prints JSON.

    python examples/bench_many.py --root /tmp/many_bench/root --folders 20 --size 800x600

Synthesises ``--folders`` photo folders (``data_synth.synthesize``, the model renderer,
seeds 0..N-1) unless they exist, warms JAX's compilation cache with one fit, then times,
each in a fresh process from its start to its end:
- ``loop``: one Python process fitting the folders one after another
  (``fitting.folder.many.fit_one_folder``, what a Dask worker runs), no Dask;
- ``dask_1``, ``dask_2``, ...: ``softshadow fit ROOT --out OUT --recursive --workers N``.
Each folder's own fit time is known (the loop prints it; Dask's workers write it in each
folder's done marker), so every run splits into time in fits and time outside them
(process and cluster start, imports, scheduling, summary): Dask's overhead is its time
outside fits minus the loop's, which the machine's load (shared, noisy) moves less than
the walls. The per-folder time is the median after each process's first folder (the first
pays tracing and compilation).
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parents[1]

LOOP = """
import json, sys, time
from pathlib import Path
from fitting import find_photo_folders
from fitting.folder.many import fit_one_folder
root, out = Path(sys.argv[1]), Path(sys.argv[2])
times = []
for folder in find_photo_folders(root):
    groups, seconds = fit_one_folder(folder, out / folder.relative_to(root), force=True)
    times.append(seconds)
print(json.dumps(times))
"""


def _synth(root: Path, n: int, preset: str, size: tuple[int, int]) -> float:
    from data_synth import synthesize
    start = time.perf_counter()
    for seed in range(n):
        folder = root / f"{preset}_{seed:02d}"
        if not (folder / "truth.json").exists():
            synthesize(folder, preset=preset, seed=seed, renderer="model", size=size, progress=False,
                       force=True)
    return time.perf_counter() - start


def _timed(cmd: list[str], env: dict) -> tuple[float, str]:
    start = time.perf_counter()
    done = subprocess.run(cmd, env=env, capture_output=True, text=True, cwd=HERE)
    seconds = time.perf_counter() - start
    if done.returncode != 0:
        raise RuntimeError(f"{cmd[:4]} failed: {done.stderr.strip().splitlines()[-1:]}")
    return seconds, done.stdout


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--root", default=None, help="where the synthetic folders are (or go)")
    parser.add_argument("--folders", type=int, default=20)
    parser.add_argument("--preset", default="pillar")
    parser.add_argument("--size", default="800x600")
    parser.add_argument("--workers", default="1,2", help="worker counts to time, comma-separated")
    parser.add_argument("--json", dest="json_path", help="also write the JSON here")
    args = parser.parse_args()
    size = tuple(int(v) for v in args.size.lower().split("x"))
    root = Path(args.root or tempfile.mkdtemp(prefix="softshadow-many-")) / "root"
    work = root.parent / "bench-out"
    synth_seconds = _synth(root, args.folders, args.preset, size)
    cache = root.parent / "jax-cache"
    env = dict(os.environ, SOFTSHADOW_JAX_CACHE=str(cache),
               PYTHONPATH=os.pathsep.join([str(HERE), os.environ.get("PYTHONPATH", "")]))
    python = sys.executable

    # Warm the persistent cache (every run below then loads the compiled solvers).
    warm, _ = _timed([python, "-m", "softshadow_cli", "fit", str(root / f"{args.preset}_00"),
                      "--out", str(work / "warm"), "--force"], env)
    shutil.rmtree(work / "loop", ignore_errors=True)
    loop_s, stdout = _timed([python, "-c", LOOP, str(root), str(work / "loop")], env)
    per_folder = json.loads(stdout.strip().splitlines()[-1])
    steady = statistics.median(per_folder[1:]) if len(per_folder) > 1 else per_folder[0]
    runs = {}
    for n in (int(v) for v in args.workers.split(",")):
        shutil.rmtree(work / f"dask_{n}", ignore_errors=True)
        seconds, _ = _timed([python, "-m", "softshadow_cli", "fit", str(root), "--out", str(work / f"dask_{n}"),
                             "--recursive", "--workers", str(n)], env)
        fits = [json.loads(m.read_text())["seconds"]
                for m in sorted((work / f"dask_{n}").rglob(".softshadow-done"))]
        runs[n] = (seconds, fits)
    n_folders = len(per_folder)
    report = {
        "date": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()),
        "machine": f"{platform.machine()}, {os.cpu_count()} cores, {platform.python_version()}",
        "preset": args.preset, "renderer": "model", "size": args.size, "folders": n_folders,
        "synth_seconds": round(synth_seconds, 1),
        "warm_cache_first_fit_seconds": round(warm, 1),
        "loop_seconds": round(loop_s, 1),
        "loop_folders_per_minute": round(60 * n_folders / loop_s, 2),
        "loop_first_folder_seconds": round(per_folder[0], 2),
        "per_folder_seconds_median": round(steady, 2),
        "loop_seconds_in_fits": round(sum(per_folder), 1),
        "loop_seconds_outside_fits": round(loop_s - sum(per_folder), 1),
        "dask": {str(n): {"seconds": round(s, 1), "folders_per_minute": round(60 * n_folders / s, 2),
                          "speedup_vs_loop": round(loop_s / s, 2), "seconds_in_fits": round(sum(f), 1),
                          "per_folder_seconds_median": round(statistics.median(f), 2),
                          "seconds_outside_fits": round(s - sum(f) / n, 1)}
                 for n, (s, f) in runs.items()},
        "dask_1_overhead_seconds": (round(runs[1][0] - sum(runs[1][1]) - (loop_s - sum(per_folder)), 1)
                                    if 1 in runs else None),
    }
    text = json.dumps(report, indent=1)
    print(text)
    if args.json_path:
        Path(args.json_path).write_text(text + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
