"""The benchmark's meshes: the built-in ones, the real MIT dragon, and decimated levels of detail.

Names: ``pillar`` (176 faces) and ``ball`` (1,472) are the built-ins; ``dragon`` is the real
Stanford dragon (an MIT-licensed remesh, decimated to the paper's 26,584 faces, vendored in
``data/`` with its licence); ``knot`` is the built-in procedural stand-in called ``dragon`` in
``softshadow.builtin_mesh`` (a rough trefoil tube, 26,600 faces).
"""

from __future__ import annotations

import functools
from pathlib import Path

import numpy as np
import trimesh

from softshadow import builtin_mesh, decimate

__all__ = ["BENCH_MESHES", "MIT_DRAGON_FULL_PATH", "MIT_DRAGON_PATH", "bench_mesh", "decimated", "mit_dragon"]

MIT_DRAGON_PATH = Path(__file__).parent / "data" / "mit_dragon_26584.ply"
#: The same dragon undecimated (41,384 faces, watertight), for the level-of-detail benchmark.
MIT_DRAGON_FULL_PATH = Path(__file__).parent / "data" / "mit_dragon_41384.ply"
BENCH_MESHES = ("pillar", "ball", "dragon", "knot")


@functools.cache
def mit_dragon(length_m: float = 1.6, full: bool = False) -> trimesh.Trimesh:
    """The vendored dragon posed on the ground: its y-up frame turned z-up, scaled to
    ``length_m`` along x (the built-in knot's size), standing on z = 0. full: the undecimated
    41,384-face mesh instead of the paper's 26,584."""
    mesh = trimesh.load(MIT_DRAGON_FULL_PATH if full else MIT_DRAGON_PATH, force="mesh", process=False)
    v = np.asarray(mesh.vertices, dtype=np.float64)
    v = np.stack([v[:, 0], -v[:, 2], v[:, 1]], axis=1)  # +90 deg about x: y up -> z up
    v *= length_m / float(np.ptp(v[:, 0]))
    v[:, 2] -= v[:, 2].min()
    return trimesh.Trimesh(v, np.asarray(mesh.faces), process=False)


def bench_mesh(name: str) -> trimesh.Trimesh:
    """One of BENCH_MESHES as a trimesh (world metres, z up, on the ground)."""
    if name == "dragon":
        return mit_dragon()
    if name == "knot":
        return builtin_mesh("dragon")
    if name in ("pillar", "ball"):
        return builtin_mesh(name)
    raise ValueError(f"unknown bench mesh {name!r}; choose one of {BENCH_MESHES}")


def decimated(mesh: trimesh.Trimesh, faces: int) -> trimesh.Trimesh:
    """A level of detail of ``mesh`` with about ``faces`` faces (``softshadow.decimate``)."""
    return decimate(mesh, faces)
