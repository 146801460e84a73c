"""The package layers and the seam between discrete (NumPy/OpenCV) and differentiable (JAX) steps.

- Imports only point down: softshadow (the renderer) <- scene <- fitting, data_synth
  <- softshadow_cli (the command line) and benchmarks (a checkout's, not installed). The one
  exception is ``softshadow/__main__.py``, the command's entry point for ``python -m softshadow``.
- A package above the renderer uses only the renderer's exported names (``softshadow.__all__``
  and ``softshadow.internal.__all__``), and ``scene``'s.
- ``fitting``'s subpackages import each other in one order, with no circles.
- The renderer's discrete modules do not import JAX.
- Discrete steps run no eager JAX operation (each would compile and dispatch a tiny XLA
  program: the sun search once made 288 of them).
"""

from __future__ import annotations

import ast
import logging
from pathlib import Path

import jax
import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("softshadow", "scene", "fitting", "data_synth", "softshadow_cli", "benchmarks")
ALLOWED = {
    "softshadow": {"softshadow"},
    "scene": {"scene", "softshadow"},
    "fitting": {"fitting", "scene", "softshadow"},
    "data_synth": {"data_synth", "scene", "softshadow"},
    "softshadow_cli": {"softshadow", "scene", "fitting", "data_synth", "softshadow_cli"},
    "benchmarks": {"softshadow", "scene", "fitting", "data_synth", "benchmarks"},
}
ENTRY_POINTS = {Path("softshadow/__main__.py")}  # may import the command line
#: fitting's subpackages, top floor first: each imports only those after it.
FITTING_FLOORS = ("folder", "solve", "samples", "edges", "photos", "report", "verdict")
PUBLIC_ONLY = ("softshadow", "scene")  # imported from above by their public names only
DISCRETE_RENDERER_MODULES = ("meshes", "camera", "occluder", "raster", "posed", "plan", "colour", "threads",
                             "shadowmap", "slides", "projector", "visibility", "clip", "sky")


def _imports(path: Path):
    """(module imported, names imported from it, line) for every import in a file."""
    tree = ast.parse(path.read_text(encoding="utf-8"))
    package = path.relative_to(ROOT).parts[0]
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            for alias in node.names:
                yield alias.name, (), node.lineno
        elif isinstance(node, ast.ImportFrom):
            if node.level:  # relative: inside the file's own package
                yield package, (), node.lineno
            else:
                yield node.module, tuple(a.name for a in node.names), node.lineno


def _files(package):
    return sorted((ROOT / package).rglob("*.py"))


@pytest.mark.parametrize("package", PACKAGES)
def test_imports_point_down(package):
    bad = []
    for path in _files(package):
        if path.relative_to(ROOT) in ENTRY_POINTS:
            continue
        for module, _, line in _imports(path):
            top = module.split(".")[0]
            if top in PACKAGES and top not in ALLOWED[package]:
                bad.append(f"{path.relative_to(ROOT)}:{line} imports {module}")
    assert not bad, "imports that point up:\n" + "\n".join(bad)


@pytest.mark.parametrize("package", [p for p in PACKAGES if p not in ("softshadow",)])
def test_lower_packages_are_used_by_their_public_names(package):
    import importlib
    exported = {p: set(importlib.import_module(p).__all__) for p in PUBLIC_ONLY}
    exported["softshadow.internal"] = set(importlib.import_module("softshadow.internal").__all__)
    bad = []
    for path in _files(package):
        if path.relative_to(ROOT) in ENTRY_POINTS:
            continue
        for module, names, line in _imports(path):
            top = module.split(".")[0]
            if top == package or top not in PUBLIC_ONLY:
                continue
            where = f"{path.relative_to(ROOT)}:{line}"
            if module not in exported:
                bad.append(f"{where} imports the submodule {module}")
                continue
            bad += [f"{where} imports {module}.{n}, not in its __all__" for n in names if n not in exported[module]]
    assert not bad, "\n".join(bad)


def _module_imports(package: str) -> dict[str, set[str]]:
    """Each module of a package (dotted) and the modules of that package it imports, at any depth of
    its code (imports inside functions included)."""
    graph: dict[str, set[str]] = {}
    for path in _files(package):
        rel = path.relative_to(ROOT).with_suffix("")
        name = ".".join(rel.parts[:-1] if rel.name == "__init__" else rel.parts)
        here = name if rel.name == "__init__" else name.rpartition(".")[0]
        targets = set()
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, ast.ImportFrom):
                if node.level:
                    base = here.rsplit(".", node.level - 1)[0] if node.level > 1 else here
                    mod = f"{base}.{node.module}" if node.module else base
                    targets |= {mod} if node.module else {f"{base}.{a.name}" for a in node.names}
                elif node.module and node.module.split(".")[0] == package:
                    targets.add(node.module)
            elif isinstance(node, ast.Import):
                targets |= {a.name for a in node.names if a.name.split(".")[0] == package}
        graph[name] = {t for t in targets if t != name}
    return graph


@pytest.mark.parametrize("package", ["fitting", "benchmarks", "softshadow", "data_synth", "scene"])
def test_no_import_circles(package):
    """No two modules import each other, directly or around a circle (imports inside functions
    included: they only hide a circle)."""
    graph = _module_imports(package)
    graph = {m: {t for t in ts if t in graph} for m, ts in graph.items()}
    state: dict[str, int] = {}
    circles = []

    def visit(node, path):
        state[node] = 1
        for nxt in sorted(graph[node]):
            if state.get(nxt) == 1:
                circles.append(" -> ".join(path[path.index(nxt):] + [nxt]))
            elif nxt not in state:
                visit(nxt, path + [nxt])
        state[node] = 2

    for node in sorted(graph):
        if node not in state:
            visit(node, [node])
    assert not circles, "import circles:\n" + "\n".join(circles)


def test_fitting_subpackages_import_downwards():
    graph = _module_imports("fitting")
    bad = []
    for module, targets in graph.items():
        parts = module.split(".")
        if len(parts) < 3:
            continue
        floor = FITTING_FLOORS.index(parts[1])
        for target in targets:
            t = target.split(".")
            if len(t) >= 2 and t[1] in FITTING_FLOORS and FITTING_FLOORS.index(t[1]) < floor:
                bad.append(f"{module} imports {target}")
    assert not bad, "imports that point up between fitting's subpackages:\n" + "\n".join(bad)


@pytest.mark.parametrize("name", DISCRETE_RENDERER_MODULES)
def test_discrete_renderer_modules_do_not_import_jax(name):
    bad = [f"line {line}: {module}" for module, _, line in _imports(ROOT / "softshadow" / f"{name}.py")
           if module == "jax" or module.startswith("jax.")]
    assert not bad, f"softshadow/{name}.py is a discrete (NumPy/OpenCV) module but imports JAX: {bad}"


class _CompileLog(logging.Handler):
    def __init__(self):
        super().__init__()
        self.compiled: list[str] = []

    def emit(self, record):
        message = record.getMessage()
        if message.startswith("Compiling "):
            self.compiled.append(message.split(" with ")[0])


@pytest.fixture
def no_eager_jax():
    """Fails the test when the code run inside ``with no_eager_jax():`` dispatches a JAX
    operation: with JAX's caches cleared, any operation would compile, and JAX logs it."""
    import contextlib

    @contextlib.contextmanager
    def guard():
        handler = _CompileLog()
        logger = logging.getLogger("jax")
        logger.addHandler(handler)
        jax.clear_caches()
        try:
            with jax.log_compiles(True):
                yield
        finally:
            logger.removeHandler(handler)
        assert not handler.compiled, f"eager JAX operations in a discrete step: {handler.compiled}"
    return guard


def test_the_guard_catches_an_eager_operation(no_eager_jax):
    import jax.numpy as jnp
    x = jnp.ones(3)
    with pytest.raises(AssertionError, match="eager JAX"):
        with no_eager_jax():
            np.asarray(jnp.sin(x))


def test_plans_run_no_eager_jax(no_eager_jax):
    from softshadow import GroundGrid, Pose, SoftShadowModel, Sun
    model = SoftShadowModel.from_mesh("pillar")
    sun, pose = Sun(150.0, 40.0), Pose((0.1, 0.2, 0.0), (0.0, 0.0, 20.0))
    grid = GroundGrid.around((-0.5, 1.0), 4.0, 96)
    points = grid.pixel_centres().reshape(-1, 3)[::7]
    # Receiver points that are not on the plane, with normals: the light-space plan.
    raised = points + np.c_[np.zeros((len(points), 2)), 0.1 * np.sin(points[:, :1])]
    normals = np.tile([0.0, 0.3, 1.0], (len(points), 1))
    with no_eager_jax():
        plan = model.plan_grid(sun, pose, grid, 0.02)
        point_plan = model.plan_points(sun, pose, points, 0.02)
        light_plan = model.plan_points(sun, pose, raised, 0.02, normals)
    assert plan.n_band > 0 and light_plan.active.any()
    leaves = (jax.tree_util.tree_leaves(point_plan) + jax.tree_util.tree_leaves(plan.plan)
              + jax.tree_util.tree_leaves(light_plan))
    assert all(isinstance(leaf, np.ndarray) for leaf in leaves), "plans hold NumPy leaves"


def test_fitting_discrete_steps_run_no_eager_jax(no_eager_jax):
    from fitting import PhotoView
    from fitting.samples.ground import select_samples
    from fitting.photos.sun_search import search_sun
    from softshadow import GroundGrid, Pose, ShadowParams, SoftShadowModel, Sun
    model = SoftShadowModel.from_mesh("pillar", profile="disk")
    sun, pose = Sun(150.0, 40.0), Pose()
    grid = GroundGrid.around((-0.9, 1.6), 2.6, 128)
    gray = 0.6 * np.asarray(model.ground_map(ShadowParams(0.01, 0.25), sun, pose, grid))
    view = PhotoView("top.png", gray, np.zeros(gray.shape, bool), grid=grid,
                     sun_azimuth_deg=150.0, sun_elevation_deg=40.0)
    with no_eager_jax():
        samples = select_samples(model, pose, view, sky_occlusion=False)
        guess = search_sun(model, pose, [view], azimuth_step=30.0, elevations=(30, 40, 50))
    assert len(samples.observed) > 50
    assert abs(guess.elevation_deg - 40.0) <= 10.0


def test_command_and_synthesis_steps_run_no_eager_jax(no_eager_jax):
    from data_synth import posed_mesh
    from softshadow import Pose, SoftShadowModel, Sun
    from softshadow_cli.render_command import _default_grid
    model = SoftShadowModel.from_mesh("ball")
    sun, pose = Sun(120.0, 35.0), Pose((0.0, 0.0, 0.5), (10.0, 0.0, 30.0))
    with no_eager_jax():
        grid = _default_grid(model, pose, sun, 64, 64, None)
        mesh = posed_mesh("ball", (0.0, 0.0, 0.5), (10.0, 0.0, 30.0), 1.0)
    assert grid.width == 64 and len(mesh.vertices) > 0


def test_code_cites_nothing_outside_the_repository():
    """Comments and docstrings point at the repository's own docs, never at files a user does not have."""
    import re
    bad = []
    for package in PACKAGES + ("examples",):
        for path in _files(package):
            for i, line in enumerate(path.read_text(encoding="utf-8").splitlines(), 1):
                if re.search(r"CONVENTIONS|\.\./shared|/work/shared", line):
                    bad.append(f"{path.relative_to(ROOT)}:{i}: {line.strip()[:100]}")
    assert not bad, "\n".join(bad)
