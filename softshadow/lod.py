"""Levels of detail of an occluder mesh: quadric-error decimation (NumPy, no JAX).

Decimation is fast-simplification's quadric edge collapse (Garland-Heckbert), called through
trimesh's ``simplify_quadric_decimation``. A series follows the Dowling paper's (its figures
6-9: 69,000 / 5,000 / 1,000 / 300 triangles), capped at the mesh's own face count: a mesh with
fewer faces than a level is used as it is for that level, and a level is not repeated.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
import trimesh

__all__ = ["PAPER_FACE_COUNTS", "LodLevel", "decimate", "lod_series"]

#: The Dowling paper's series of triangle counts (figures 6-9), finest first.
PAPER_FACE_COUNTS = (69_000, 5_000, 1_000, 300)


class LodLevel(NamedTuple):
    """One level of a series: the mesh, its face count, the count asked for (the mesh's own
    count for the undecimated level) and whether the mesh is watertight."""

    mesh: trimesh.Trimesh
    faces: int
    target: int
    watertight: bool


def decimate(mesh: trimesh.Trimesh, faces: int) -> trimesh.Trimesh:
    """``mesh`` decimated to about ``faces`` faces (quadric error, fast-simplification; within
    a few faces of the target); the mesh itself when it has no more faces than that.

    Vertices (m, 3) in the mesh's own units; the result is a plain trimesh (process=False).
    """
    if faces < 4:
        raise ValueError(f"a level of detail needs at least 4 faces, got {faces}")
    if faces >= len(mesh.faces):
        return mesh
    out = mesh.simplify_quadric_decimation(face_count=int(faces))
    return trimesh.Trimesh(np.asarray(out.vertices, dtype=np.float64), np.asarray(out.faces), process=False)


def lod_series(mesh: trimesh.Trimesh, face_counts=PAPER_FACE_COUNTS) -> list[LodLevel]:
    """Levels of detail of ``mesh``, finest first: one per count in ``face_counts``, each
    capped at the mesh's face count (the first capped level is the mesh itself); counts that
    would repeat a level are dropped.

    face_counts: target triangle counts (any order; sorted finest first).
    """
    n_full = len(mesh.faces)
    out: list[LodLevel] = []
    for target in sorted({int(f) for f in face_counts}, reverse=True):
        level = decimate(mesh, min(target, n_full))
        faces = len(level.faces)
        if out and faces >= out[-1].faces:
            continue  # capped at the same mesh as the level before
        out.append(LodLevel(level, faces, min(target, n_full), bool(level.is_watertight)))
    return out
