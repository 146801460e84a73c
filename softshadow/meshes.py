"""Occluder meshes: the built-in shapes and loading any file trimesh reads (NumPy).

Built-ins are sized like the seed's Table 3 and live in their own frame:
metres, z up, the origin on the ground under the object.

- ``pillar``: a 0.2 x 0.2 x 3.0 m square post, 176 triangles.
- ``ball``: a sphere of radius 0.5 m centred 1.5 m above the origin (a ball on
  an invisible stand, so its whole shadow is a soft ellipse), 1,472 triangles.
- ``dragon``: a rough, knotted tube with through-holes standing on the ground,
  about 26,600 triangles, made procedurally (no download).
"""

from __future__ import annotations

import functools
from pathlib import Path

import numpy as np
import trimesh

__all__ = ["BUILTIN_MESHES", "MeshError", "builtin_mesh", "load_mesh", "pillar", "ball", "dragon",
           "clean_mesh"]


class MeshError(ValueError):
    """A mesh that cannot be used as an occluder, with the reason."""


def pillar(width: float = 0.2, height: float = 3.0, segments: int = 21) -> trimesh.Trimesh:
    """Square post standing on z = 0, sides split into ``segments`` rows (176 faces)."""
    h = width / 2.0
    corners = np.array([[h, h], [-h, h], [-h, -h], [h, -h]])  # counter-clockwise from above
    zs = np.linspace(0.0, height, segments + 1)
    ring = np.array([[x, y, z] for z in zs for x, y in corners])
    bottom_c = len(ring)
    top_c = bottom_c + 1
    vertices = np.vstack([ring, [[0, 0, 0.0]], [[0, 0, height]]])
    faces = []
    for j in range(segments):
        for i in range(4):
            a, b = j * 4 + i, j * 4 + (i + 1) % 4
            c, d = a + 4, b + 4
            faces += [[a, b, d], [a, d, c]]  # outward normals
    top = segments * 4
    for i in range(4):
        faces.append([top_c, top + i, top + (i + 1) % 4])
        faces.append([bottom_c, (i + 1) % 4, i])
    mesh = trimesh.Trimesh(vertices, np.array(faces), process=False)
    mesh.fix_normals()
    return mesh


def ball(radius: float = 0.5, centre_height: float = 1.5, sectors: int = 32,
         rings: int = 24) -> trimesh.Trimesh:
    """UV sphere (32 sectors, 24 rings: 1,472 faces) floating ``centre_height`` above the ground."""
    theta = np.linspace(0.0, np.pi, rings + 1)[1:-1]  # polar angles of the inner latitude rows
    phi = np.linspace(0.0, 2 * np.pi, sectors, endpoint=False)
    t, p = np.meshgrid(theta, phi, indexing="ij")
    rows = np.stack([np.sin(t) * np.cos(p), np.sin(t) * np.sin(p), np.cos(t)], -1).reshape(-1, 3)
    north, south = len(rows), len(rows) + 1
    vertices = np.vstack([rows, [[0, 0, 1.0]], [[0, 0, -1.0]]]) * radius
    faces = []
    for i in range(sectors):
        j = (i + 1) % sectors
        faces.append([north, i, j])
        last = (rings - 2) * sectors
        faces.append([south, last + j, last + i])
        for r in range(rings - 2):
            a, b = r * sectors + i, r * sectors + j
            faces += [[a, a + sectors, b + sectors], [a, b + sectors, b]]
    mesh = trimesh.Trimesh(vertices, np.array(faces), process=False)
    mesh.fix_normals()
    mesh.apply_translation([0.0, 0.0, centre_height])
    return mesh


def dragon(seed: int = 7) -> trimesh.Trimesh:
    """A rough trefoil-knot tube on the ground: holes, self-shadowing, ~26,600 faces.

    The tube follows a trefoil knot scaled to about 1.6 m across and 1.2 m
    high, with a radius that swells and shrinks along the body and a rough
    multi-frequency displacement; it stands on the ground (min z = 0).
    """
    n_along, n_around = 700, 19  # 2 * 700 * 19 = 26,600 triangles
    rng = np.random.default_rng(seed)
    u = np.linspace(0.0, 2 * np.pi, n_along, endpoint=False)
    v = np.linspace(0.0, 2 * np.pi, n_around, endpoint=False)
    # Trefoil centre line (x, y horizontal; z up).
    centre = np.stack([np.sin(u) + 2 * np.sin(2 * u), np.cos(u) - 2 * np.cos(2 * u),
                       -np.sin(3 * u)], axis=1) * np.array([0.27, 0.27, 0.35])
    tangent = np.gradient(centre, axis=0)
    tangent /= np.linalg.norm(tangent, axis=1, keepdims=True)
    ref = np.array([0.0, 0.0, 1.0])
    normal = np.cross(tangent, ref)
    normal /= np.linalg.norm(normal, axis=1, keepdims=True)
    binormal = np.cross(tangent, normal)
    radius = 0.11 + 0.05 * np.sin(3 * u + 0.5) ** 2
    phase = rng.uniform(0, 2 * np.pi, size=4)
    uu, vv = np.meshgrid(u, v, indexing="ij")
    rough = (0.10 * np.sin(11 * uu + 3 * vv + phase[0]) + 0.06 * np.sin(23 * uu - 5 * vv + phase[1])
             + 0.04 * np.sin(47 * uu + 7 * vv + phase[2]) + 0.03 * rng.standard_normal(uu.shape))
    r = radius[:, None] * (1.0 + rough)
    pts = (centre[:, None, :] + r[..., None] * (np.cos(vv)[..., None] * normal[:, None, :]
                                                 + np.sin(vv)[..., None] * binormal[:, None, :]))
    vertices = pts.reshape(-1, 3)
    i = np.arange(n_along)[:, None]
    j = np.arange(n_around)[None, :]
    a = i * n_around + j
    b = ((i + 1) % n_along) * n_around + j
    c = ((i + 1) % n_along) * n_around + (j + 1) % n_around
    d = i * n_around + (j + 1) % n_around
    faces = np.concatenate([np.stack([a, b, c], -1).reshape(-1, 3),
                            np.stack([a, c, d], -1).reshape(-1, 3)])
    mesh = trimesh.Trimesh(vertices, faces, process=False)
    mesh.fix_normals()
    mesh.apply_translation([0.0, 0.0, -mesh.bounds[0, 2]])
    return mesh


BUILTIN_MESHES = {"pillar": pillar, "ball": ball, "dragon": dragon}


@functools.lru_cache(maxsize=8)
def _builtin_cached(name: str) -> trimesh.Trimesh:
    return BUILTIN_MESHES[name]()


def builtin_mesh(name: str) -> trimesh.Trimesh:
    """A fresh copy of a built-in mesh by name."""
    if name not in BUILTIN_MESHES:
        raise MeshError(f"unknown built-in mesh {name!r}; choose one of {sorted(BUILTIN_MESHES)}")
    return _builtin_cached(name).copy()


def clean_mesh(mesh: trimesh.Trimesh, source: str = "mesh") -> trimesh.Trimesh:
    """Validate a mesh for shadow casting; drop unusable faces, raise MeshError if none remain.

    Non-finite vertices, out-of-range indices and zero-area faces are removed
    (they cast no shadow); duplicate faces are kept, as they change nothing.
    """
    vertices = np.asarray(mesh.vertices, dtype=np.float64)
    faces = np.asarray(mesh.faces, dtype=np.int64)
    if vertices.ndim != 2 or vertices.shape[-1] != 3 or len(vertices) == 0:
        raise MeshError(f"{source}: no vertices")
    if faces.ndim != 2 or faces.shape[-1] != 3 or len(faces) == 0:
        raise MeshError(f"{source}: no triangle faces")
    ok = np.all((faces >= 0) & (faces < len(vertices)), axis=1)
    faces = faces[ok]
    finite_v = np.all(np.isfinite(vertices), axis=1)
    faces = faces[np.all(finite_v[faces], axis=1)]
    if len(faces):
        tri = vertices[faces]
        area2 = np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1)
        scale = max(np.ptp(vertices[finite_v], axis=0).max(), 1e-12)
        faces = faces[area2 > 1e-12 * scale * scale]
    if len(faces) == 0:
        raise MeshError(f"{source}: every face is degenerate or has non-finite vertices")
    vertices = np.where(np.isfinite(vertices), vertices, 0.0)
    return trimesh.Trimesh(vertices, faces, process=False)


def load_mesh(name_or_path: str | Path, base_dir: str | Path | None = None) -> trimesh.Trimesh:
    """A built-in mesh by name, or any file trimesh reads (scenes are concatenated).

    Relative paths are resolved against ``base_dir`` (the photo folder).
    Raises MeshError with the reason when the file is missing or unusable.
    """
    name = str(name_or_path)
    if name in BUILTIN_MESHES:
        return builtin_mesh(name)
    path = Path(name)
    if base_dir is not None and not path.is_absolute():
        path = Path(base_dir) / path
    if not path.exists():
        raise MeshError(f"mesh file {path} not found (built-ins: {sorted(BUILTIN_MESHES)})")
    try:
        loaded = trimesh.load(path, force="mesh", process=False)
    except Exception as exc:  # trimesh raises many types for broken files
        # Its messages describe the parser's trouble ("'utf-8' codec can't decode ..."), not the
        # file's: say what the user needs to know, and keep the parser's words as the cause.
        raise MeshError(f"{path.name} is not a mesh that can be read ({path.suffix or 'no extension'} "
                        f"file; trimesh: {type(exc).__name__})") from exc
    if not isinstance(loaded, trimesh.Trimesh):
        raise MeshError(f"{path} holds no triangle mesh")
    return clean_mesh(loaded, str(path))
