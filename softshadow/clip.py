"""Clipping triangles at a camera's near plane (NumPy, discrete).

A perspective z-buffer (the camera's ``visibility``, a projector's shadow map) cannot
project a corner at or behind the camera's plane. Dropping such faces would leave holes
where a large receiver (a floor) passes under and behind the camera; instead each face is
cut at depth ``near``: one corner in front gives one smaller triangle, two give two. The
pieces lie in their face's plane and keep its winding, and each names its source face.
"""

from __future__ import annotations

import numpy as np

__all__ = ["clip_near"]


def clip_near(vertices: np.ndarray, depth: np.ndarray, faces: np.ndarray,
              near: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The parts of faces (F, 3) with depth > near.

    vertices (V, 3) (any coordinates affine in the world's, e.g. world metres); depth (V,) each
    vertex's depth along the camera's axis. Returns (vertices (V', 3): the originals then the cut
    points, faces (F', 3) into them, source (F',) the face each piece comes from).
    """
    vertices = np.asarray(vertices, np.float64)
    depth = np.asarray(depth, np.float64)
    faces = np.asarray(faces, np.int64).reshape(-1, 3)
    front = depth[faces] > near
    n_front = front.sum(1)
    keep = np.flatnonzero(n_front == 3)
    out_faces, out_source, new_vertices = [faces[keep]], [keep], []
    next_id = len(vertices)
    for count in (1, 2):
        idx = np.flatnonzero(n_front == count)
        if not len(idx):
            continue
        # Rotate each face so its odd corner (the one in front for count 1, behind for count 2)
        # comes first; a rotation keeps the winding.
        odd = front[idx] if count == 1 else ~front[idx]
        r = np.argmax(odd, axis=1)
        rot = faces[idx[:, None], (r[:, None] + np.arange(3)) % 3]
        a, b, c = rot[:, 0], rot[:, 1], rot[:, 2]

        def cut(p, q):
            t = (near - depth[p]) / (depth[q] - depth[p])
            return vertices[p] + t[:, None] * (vertices[q] - vertices[p])

        ab, ac = cut(a, b), cut(a, c)
        m = len(idx)
        id_ab = next_id + np.arange(m)
        id_ac = next_id + m + np.arange(m)
        next_id += 2 * m
        new_vertices += [ab, ac]
        if count == 1:  # a in front: the triangle (a, ab, ac)
            out_faces.append(np.stack([a, id_ab, id_ac], 1))
            out_source.append(idx)
        else:  # a behind: the quad (ab, b, c, ac) as two triangles
            out_faces += [np.stack([id_ab, b, c], 1), np.stack([id_ab, c, id_ac], 1)]
            out_source += [idx, idx]
    all_vertices = np.vstack([vertices, *new_vertices]) if new_vertices else vertices
    return all_vertices, np.vstack(out_faces).astype(np.int64), np.concatenate(out_source).astype(np.int64)
