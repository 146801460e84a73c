"""A fresh process loads only what its path needs (docs/fitting.md, start-up and caches).

JAX, equinox, optimistix and trimesh take seconds to import. ``softshadow`` and ``fitting``
import their modules on first use (``lazy_loader``), so ``softshadow --help`` and the fit of
photos without geometry never load them. Each check runs in a fresh interpreter (this test
process has loaded everything already) and takes about a second.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from softshadow.compilation_cache import MIN_COMPILE_SECONDS

ROOT = Path(__file__).resolve().parents[1]
HEAVY = ("jax", "equinox", "optimistix", "trimesh", "numba", "dask", "pandas")


def _loaded_after(code: str, env: dict | None = None) -> dict:
    """Run ``code`` in a fresh interpreter from the repository root; return what it prints last
    (a JSON object) with the heavy modules it loaded under "heavy"."""
    script = code + f"\nimport json, sys\nprint(json.dumps({{'heavy': [m for m in {HEAVY!r} if m in sys.modules]}}))\n"
    run = subprocess.run([sys.executable, "-c", script], cwd=ROOT, capture_output=True, text=True, timeout=120,
                         env={**os.environ, "PYTHONPATH": str(ROOT), **(env or {})})
    assert run.returncode == 0, run.stderr[-2000:]
    return json.loads(run.stdout.strip().splitlines()[-1])


def test_the_check_sees_a_heavy_import():
    # A stand-in module under a heavy name (importing a real one takes seconds).
    assert _loaded_after("import sys, types; sys.modules['trimesh'] = types.ModuleType('trimesh')")["heavy"] == [
        "trimesh"]


@pytest.mark.parametrize("package", ["softshadow", "scene", "fitting"])
def test_importing_a_package_loads_nothing_heavy(package):
    assert _loaded_after(f"import {package}")["heavy"] == []


def test_help_and_argument_parsing_load_nothing_heavy():
    code = ("import contextlib, io\nfrom softshadow_cli import main\n"
            "for argv in (['--help'], ['fit', '--help'], ['render', '--help']):\n"
            "    with contextlib.redirect_stdout(io.StringIO()), contextlib.suppress(SystemExit):\n"
            "        main(argv)\n")
    assert _loaded_after(code)["heavy"] == []


def test_synth_help_still_lists_the_presets(capsys):
    from softshadow_cli import main
    with pytest.raises(SystemExit) as exit_:
        main(["synth", "--help"])
    assert exit_.value.code == 0 and "--preset" in capsys.readouterr().out
    with pytest.raises(SystemExit):
        main(["synth", "out", "--preset", "no-such-preset"])
    assert "invalid choice: 'no-such-preset'" in capsys.readouterr().err


def test_a_fit_without_geometry_loads_no_jax_or_trimesh(tmp_path):
    # A soft-edged shadow on a textured ground, no scene.toml: measured edge by edge (no JAX).
    from PIL import Image
    rng = np.random.default_rng(0)
    h, w = 240, 320
    x = np.arange(w)[None, :] - 150 - 0.15 * np.arange(h)[:, None]
    alpha = np.clip(0.5 - x / 6.0, 0.0, 1.0)
    linear = 0.6 * (1.0 - alpha * (1.0 - 0.25)) * (1.0 + 0.03 * rng.standard_normal((h, w)))
    srgb = np.clip(255.0 * np.clip(linear, 0, 1) ** (1 / 2.2), 0, 255).astype(np.uint8)
    Image.fromarray(np.dstack([srgb] * 3)).save(tmp_path / "edge.png")
    out = tmp_path / "out"
    code = ("import contextlib, io, sys\nfrom softshadow_cli import main\n"
            "with contextlib.redirect_stdout(io.StringIO()):\n"
            f"    code = main(['fit', {str(tmp_path)!r}, '--out', {str(out)!r}, '--no-plots'])\n")
    assert _loaded_after(code)["heavy"] == []
    (group,) = json.loads((out / "results.json").read_text())["groups"]
    assert group["rho"] == pytest.approx(0.25, abs=0.05)


def test_compilation_cache_settings_reach_jax_imported_later(tmp_path):
    code = ("import sys\nfrom softshadow import use_compilation_cache\n"
            f"use_compilation_cache({str(tmp_path)!r})\nassert 'jax' not in sys.modules\n"
            "import jax\nprint(jax.config.jax_compilation_cache_dir, jax.config.jax_persistent_cache_min_compile_time_secs)\n")
    run = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, timeout=120,
                         env={**os.environ, "PYTHONPATH": str(ROOT)})
    assert run.returncode == 0, run.stderr[-2000:]
    assert run.stdout.split() == [str(tmp_path), str(MIN_COMPILE_SECONDS)]


@pytest.mark.parametrize("package", ["softshadow", "fitting"])
def test_every_public_name_resolves_to_its_module_object(package):
    import importlib
    pkg = importlib.import_module(package)
    for name in pkg.__all__:
        value = getattr(pkg, name)
        home = getattr(value, "__module__", None)
        if home and home.startswith(package + "."):
            assert getattr(sys.modules[home], name.split(".")[-1], value) is value
    with pytest.raises(AttributeError):
        pkg.no_such_name  # noqa: B018 (the lookup is the test)


def test_one_blas_thread_entered_first_still_limits_every_blas():
    # The CLI enters it before anything has loaded NumPy, SciPy or OpenCV (each brings its own
    # OpenBLAS); threadpoolctl limits only libraries already loaded.
    code = ("from softshadow import one_blas_thread\nfrom threadpoolctl import threadpool_info\n"
            "with one_blas_thread():\n    import numpy, scipy.linalg, cv2\n"
            "    blas = [i['num_threads'] for i in threadpool_info() if i['user_api'] == 'blas']\n"
            "print(blas)\n")
    run = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, timeout=120,
                         env={**os.environ, "PYTHONPATH": str(ROOT)})
    assert run.returncode == 0, run.stderr[-2000:]
    blas = json.loads(run.stdout.strip().splitlines()[-1])
    assert len(blas) >= 2 and set(blas) == {1}


def test_no_plots_asks_the_fit_for_no_plot_data(monkeypatch):
    # The rule book judges the fit's evidence, not its plot data: under --no-plots the fit builds
    # neither the profiles nor the overlays (a render of the fitted shadow, 0.4-0.5 s a group).
    import types

    import fitting.folder.checked as checked
    import fitting.solve.group as solve
    from fitting import FitOptions, GroupResult, PhotoGroup
    asked = []

    def fit_group(model, pose, views, label, time, options, *more, **kw):
        asked.append(options.plots)
        return GroupResult.failed(label, time, [v.name for v in views], "stopped here")
    monkeypatch.setattr(solve, "fit_group", fit_group)
    views = [types.SimpleNamespace(name="a.jpg", sun_source="scene")]
    for plots in (False, True):
        checked.fit_checked(None, None, views, PhotoGroup("10:30", "10:30", ["a.jpg"]), FitOptions(plots=plots))
    assert asked == [False, True]


def test_numba_caches_go_to_the_users_cache_folder_not_beside_the_modules(tmp_path):
    """A cache file beside an installed module outlives its uninstall as a bare ``softshadow/`` folder,
    which hides a later editable install; NUMBA_CACHE_DIR, when set, wins."""
    code = ("import os\nimport softshadow\nimport numba.core.config as c\nprint(c.CACHE_DIR)\n")
    env = {k: v for k, v in os.environ.items() if k != "NUMBA_CACHE_DIR"}
    env.update(HOME=str(tmp_path), PYTHONPATH=str(ROOT))
    run = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, timeout=120, env=env)
    assert run.returncode == 0, run.stderr[-2000:]
    assert run.stdout.strip() == str(tmp_path / ".cache" / "softshadow" / "numba")
    env["NUMBA_CACHE_DIR"] = str(tmp_path / "mine")
    run = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, timeout=120, env=env)
    assert run.stdout.strip() == str(tmp_path / "mine")


def _compiled_loops():
    """Every compiled loop the packages make ((where, dispatcher)): what their loop factories
    (``functools.cache``d functions of no arguments) return."""
    import importlib
    import inspect
    import pkgutil

    from numba.core.registry import CPUDispatcher

    import data_synth
    import fitting
    import softshadow

    loops = []
    for package in (softshadow, fitting, data_synth):
        for info in pkgutil.walk_packages(package.__path__, package.__name__ + "."):
            if info.name.endswith("__main__"):
                continue
            module = importlib.import_module(info.name)
            for name, factory in vars(module).items():
                if not (callable(factory) and hasattr(factory, "cache_info")
                        and getattr(factory, "__module__", None) == module.__name__
                        and not inspect.signature(factory).parameters):
                    continue
                made = factory()
                for loop in made if isinstance(made, tuple) else (made,):
                    if isinstance(loop, CPUDispatcher):
                        loops.append((f"{module.__name__}.{name}: {loop.py_func.__name__}", loop))
    return loops


def test_no_compiled_loop_closes_over_a_dispatcher():
    """numba keys a cached loop by its closure's contents, pickled, and a dispatcher pickles with an
    identifier drawn anew in each process: such a loop would be compiled again in every process
    (helpers are ``parallel_loops.loop_helper``s, plain functions)."""
    from numba.core.registry import CPUDispatcher

    loops = _compiled_loops()
    assert len(loops) > 30  # the walk found the packages' loops
    closing = [where for where, loop in loops
               if any(isinstance(cell.cell_contents, CPUDispatcher) for cell in loop.py_func.__closure__ or ())]
    assert closing == []


def test_a_second_process_loads_a_loop_with_helpers_from_the_cache(tmp_path):
    """The distance transform's loop (with an inlined helper) compiled once, then loaded."""
    code = ("import numpy as np\nfrom softshadow.raster import _chamfer_kernel\n"
            "src = np.ones((9, 9), np.uint8); src[4, 4] = 0; label = np.zeros((9, 9), np.int32); label[4, 4] = 1\n"
            "dist = np.full((9, 9), np.inf, np.float32); near = np.full((9, 9), -1, np.int32)\n"
            "_chamfer_kernel()(src, label, np.array([[4, 4]]), 0, 9, 0, 9, 0, 9, 18, 8, dist, near)\n"
            "assert dist[4, 6] == 2.0 and near[4, 6] == 0\n")
    env = {**os.environ, "NUMBA_CACHE_DIR": str(tmp_path), "NUMBA_DEBUG_CACHE": "1", "PYTHONPATH": str(ROOT)}
    logs = []
    for _ in range(2):
        run = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, timeout=300,
                             env=env)
        assert run.returncode == 0, run.stderr[-2000:]
        logs.append(run.stdout + run.stderr)
    assert "data saved" in logs[0] and "_chamfer_kernel" in logs[0]
    assert "data loaded" in logs[1] and "data saved" not in logs[1]
