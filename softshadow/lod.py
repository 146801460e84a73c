"""Levels of detail of an occluder mesh: quadric-error decimation (NumPy, no JAX).

Decimation is fast-simplification's quadric edge collapse (Garland-Heckbert), called through
trimesh's ``simplify_quadric_decimation``. Collapsing edges can pinch a closed surface: two
sheets of it come to share an edge (four faces on it; the real dragon's 1,000- and 300-face
levels). ``decimate`` then gives each sheet its own copies of the shared vertices
(``split_pinched``), so that a closed mesh's levels stay closed (the renderer draws a closed
mesh's lit faces only, and its silhouette is where lit meets unlit). A series follows the Dowling paper's (its figures
6-9: 69,000 / 5,000 / 1,000 / 300 triangles), capped at the mesh's own face count: a mesh with
fewer faces than a level is used as it is for that level, and a level is not repeated.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
import trimesh
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

__all__ = ["PAPER_FACE_COUNTS", "LodLevel", "decimate", "lod_series", "split_pinched"]

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
    a few faces of the target); the mesh itself when it has no more faces than that. A
    watertight mesh's level is watertight wherever splitting pinched vertices makes it so
    (``split_pinched``).

    Vertices (m, 3) in the mesh's own units; the result is a plain trimesh (process=False).
    """
    if faces < 4:
        raise ValueError(f"a level of detail needs at least 4 faces, got {faces}")
    if faces >= len(mesh.faces):
        return mesh
    out = mesh.simplify_quadric_decimation(face_count=int(faces))
    level = trimesh.Trimesh(np.asarray(out.vertices, dtype=np.float64), np.asarray(out.faces), process=False)
    if mesh.is_watertight and not level.is_watertight:
        level = split_pinched(level)
    return level


def split_pinched(mesh: trimesh.Trimesh) -> trimesh.Trimesh:
    """``mesh`` with each vertex split into one copy per fan of its faces: faces around a
    vertex belong to one fan when they are joined through edges that have exactly two faces.
    A closed surface pinched at an edge (two sheets sharing it, four faces on it) or at a
    vertex then becomes a closed surface with coincident vertices; the triangles do not move.

    Returns the split mesh when it is watertight and consistently wound, else ``mesh`` itself
    (an open or otherwise broken mesh is left as it is). Vertices that gain no copy keep their
    index; the copies are appended.
    """
    faces = np.asarray(mesh.faces, np.int64)
    n_faces = len(faces)
    if not n_faces:
        return mesh
    # Corner c = 3 f + k is vertex faces[f, k]; slot k's edge runs from corner k to corner k + 1.
    start = np.arange(3 * n_faces)
    end = start - start % 3 + (start % 3 + 1) % 3
    vertex = faces.reshape(-1)
    edge = np.sort(np.stack([vertex[start], vertex[end]], 1), axis=1)
    _, edge_id, uses = np.unique(edge, axis=0, return_inverse=True, return_counts=True)
    edge_id = edge_id.reshape(-1)
    # The two slots of each two-faced edge, side by side.
    two = np.flatnonzero(uses[edge_id] == 2)
    two = two[np.argsort(edge_id[two], kind="stable")].reshape(-1, 2)
    p, q = two[:, 0], two[:, 1]
    # Each such edge joins the corners at its two vertices: p's start with q's end where the faces
    # run along it in opposite directions (consistent winding), else start with start.
    opposite = vertex[p] == vertex[end[q]]
    a = np.concatenate([p, end[p]])
    b = np.concatenate([np.where(opposite, end[q], q), np.where(opposite, q, end[q])])
    graph = coo_matrix((np.ones(len(a), np.int8), (a, b)), shape=(3 * n_faces, 3 * n_faces))
    n_fans, fan = connected_components(graph, directed=False)
    used, first_corner = np.unique(vertex, return_index=True)
    if n_fans == len(used):
        return mesh  # one fan per vertex: nothing is pinched
    # Each vertex keeps its index for the fan of its first corner; its other fans get new vertices.
    fan_vertex = np.empty(n_fans, np.int64)
    fan_vertex[fan] = vertex
    keeps = np.zeros(n_fans, bool)
    keeps[fan[first_corner]] = True
    index = fan_vertex.copy()
    index[~keeps] = len(mesh.vertices) + np.arange(int((~keeps).sum()))
    vertices = np.asarray(mesh.vertices, np.float64)
    split = trimesh.Trimesh(np.concatenate([vertices, vertices[fan_vertex[~keeps]]]), index[fan].reshape(-1, 3),
                            process=False)
    return split if split.is_watertight and split.is_winding_consistent else mesh


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
