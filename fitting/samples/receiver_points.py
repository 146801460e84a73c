"""Where a photo's pixels meet the receiver: 3-D points, normals and pixel Jacobians (NumPy, trimesh).

Three receivers (scene.toml ``[receiver]``):

- ``plane``: the ground z = 0 (rays meet it analytically);
- ``depth``: a range image seen by the photo's own camera, each value the
  distance along the optical axis (z_cam): a pixel (u, v) with depth z lies at
  x_cam = z K^-1 (u, v, 1), x_world = R^T (x_cam - t). Normals come from the
  back-projected neighbours (central differences over +-2 pixels), turned to
  face the camera; ``.npy`` holds float32 metres (NaN: no data), 16-bit
  ``.png`` millimetres (0: no data);
- ``mesh``: any mesh in world metres; each pixel's ray is cast against it
  (trimesh, Embree when installed) and the hit face's normal is used.

Each answers, for pixels (col, row), the point, the unit normal, whether the
pixel sees the receiver, and d(point)/d(col, row) (3, 2): the local tangent
plane cut by the rays through the pixel's neighbours half a pixel away (exact
on flat faces). ``blocker_mesh`` gives the receiver as something that hides
sky and sun (the mesh, or the range image's surface as a triangle mesh).
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import cv2
import numpy as np
import trimesh

from softshadow import PinholeCamera, load_mesh
from softshadow.internal import pose_matrix

__all__ = ["ReceiverError", "ReceiverSurface", "read_depth", "depth_points", "depth_mesh", "receiver_for_photo",
           "load_receiver_mesh"]


class ReceiverError(ValueError):
    """The receiver cannot be modelled for a photo (one-line reason)."""


def read_depth(path, shape: tuple[int, int]) -> np.ndarray:
    """A range image (H, W) float64 of z_cam metres, NaN where there is no data.

    ``.npy``: float metres, NaN = no data. ``.png``: 16-bit millimetres, 0 = no data.
    shape: the photo's (H, W); a range image of twice that size (a photo read at half size)
    is reduced by taking every other pixel's mean.
    """
    path = Path(path)
    if not path.exists():
        raise ReceiverError(f"range image {path.name} not found")
    name = path.name.lower()
    if name.endswith(".npy"):
        try:
            depth = np.load(path, allow_pickle=False).astype(np.float64)
        except (OSError, ValueError) as exc:
            raise ReceiverError(f"cannot read range image {path.name}: {exc}") from exc
    elif name.endswith(".png"):
        raw = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
        if raw is None:
            raise ReceiverError(f"cannot read range image {path.name}")
        if raw.dtype != np.uint16 or raw.ndim != 2:
            raise ReceiverError(f"range image {path.name} must be a 16-bit single-channel PNG of millimetres")
        depth = np.where(raw > 0, raw.astype(np.float64) / 1000.0, np.nan)
    else:
        raise ReceiverError(f"range image {path.name}: use .npy (metres) or 16-bit .png (millimetres)")
    if depth.ndim != 2:
        raise ReceiverError(f"range image {path.name} must be two-dimensional, got shape {depth.shape}")
    h, w = shape
    if depth.shape == (2 * h, 2 * w):
        depth = np.nanmean(depth.reshape(h, 2, w, 2), axis=(1, 3)) if np.isfinite(depth).any() else depth[::2, ::2]
    if depth.shape != (h, w):
        raise ReceiverError(f"range image {path.name} is {depth.shape[1]}x{depth.shape[0]}, "
                            f"the photo {w}x{h}: they must match")
    negative = np.isfinite(depth) & (depth < 0)
    if negative.any():
        raise ReceiverError(f"range image {path.name} holds negative depths ({_share(negative)} of its pixels, "
                            f"down to {_metres(depth[negative].min())}): each value is the distance along the "
                            "camera's optical axis, positive in front of it")
    depth = np.where(np.isfinite(depth) & (depth > 0), depth, np.nan)
    if not np.isfinite(depth).any():
        raise ReceiverError(f"range image {path.name} holds no valid depth")
    if np.nanmedian(depth) > MAX_MEDIAN_DEPTH_M:
        raise ReceiverError(f"range image {path.name}: its depths run {_span(depth)}, too far for a shadow to be "
                            f"measured: {_unit_hint(path.name, 1000.0)}")
    return depth


#: The largest median depth (metres) a range image may have: beyond it, the unit is wrong.
MAX_MEDIAN_DEPTH_M = 1000.0
#: A range image's median depth may differ from the camera's distance to the object by this factor.
DEPTH_SCALE_FACTOR = 20.0


def _share(mask: np.ndarray) -> str:
    share = 100 * float(mask.mean())
    return f"{share:.2g} %" if share < 10 else f"{share:.0f} %"


def _metres(x: float) -> str:
    x = float(x)
    if abs(x) >= 1000:
        return f"{x / 1000:.3g} km"
    if abs(x) < 0.1:
        return f"{x * 1000:.3g} mm"
    return f"{x:.3g} m"


def _span(depth: np.ndarray) -> str:
    lo, med, hi = np.nanpercentile(depth, [1, 50, 99])
    return f"{_metres(lo)} to {_metres(hi)} (median {_metres(med)})"


def _unit_hint(name: str, ratio: float) -> str:
    """What a range image whose depths are ``ratio`` times too large probably holds."""
    stored = ".npy holds metres" if name.lower().endswith(".npy") else "a 16-bit .png holds millimetres"
    if ratio > 1:
        guess = "millimetres read as metres?" if ratio > 100 else "a unit smaller than the file's?"
    else:
        guess = "metres read as millimetres?" if ratio < 0.01 else "a unit larger than the file's?"
    return f"{guess} ({stored})"


def _check_depth_scale(depth: np.ndarray, name: str, camera_centre: np.ndarray, object_position) -> None:
    """A ReceiverError when the range image's median depth is far (DEPTH_SCALE_FACTOR) from the
    camera's distance to the object: the depths are in another unit than the file's."""
    distance = float(np.linalg.norm(np.asarray(camera_centre, float) - np.asarray(object_position, float)))
    median = float(np.nanmedian(depth))
    if distance <= 0 or not np.isfinite(median):
        return
    ratio = median / distance
    if 1 / DEPTH_SCALE_FACTOR <= ratio <= DEPTH_SCALE_FACTOR:
        return
    raise ReceiverError(f"range image {name}: its depths run {_span(depth)}, but the camera stands "
                        f"{_metres(distance)} from the object: {_unit_hint(name, ratio)}")


def depth_points(depth: np.ndarray, camera: PinholeCamera) -> np.ndarray:
    """World points (H, W, 3) of a range image (NaN where it has no data)."""
    h, w = depth.shape
    rows, cols = np.mgrid[0:h, 0:w]
    kinv = np.linalg.inv(camera.K)
    x = kinv[0, 0] * cols + kinv[0, 1] * rows + kinv[0, 2]
    y = kinv[1, 1] * rows + kinv[1, 2]
    cam = np.stack([x * depth, y * depth, depth], -1)
    return (cam - camera.t) @ camera.R  # R^T (x_cam - t), row-wise


def _depth_normals(points: np.ndarray, centre: np.ndarray, span: int = 2,
                   max_jump: float = 0.05) -> tuple[np.ndarray, np.ndarray]:
    """Unit normals (H, W, 3) facing the camera and their validity (H, W) from a point image.

    Central differences over +-span pixels; invalid where a neighbour has no data or lies
    more than max_jump (relative to its distance from the camera) off the others (a depth
    discontinuity: an edge in front of the background).
    """
    h, w, _ = points.shape
    pad = np.pad(points, ((span, span), (span, span), (0, 0)), constant_values=np.nan)
    right, left = pad[span:-span, 2 * span:], pad[span:-span, :-2 * span]
    down, up = pad[2 * span:, span:-span], pad[:-2 * span, span:-span]
    n = np.cross(right - left, down - up)
    norm = np.linalg.norm(n, axis=-1, keepdims=True)
    n = n / np.where(norm > 0, norm, 1.0)
    to_cam = centre - points
    flip = np.sum(n * to_cam, -1) < 0
    n[flip] *= -1
    dist = np.linalg.norm(to_cam, axis=-1)
    with np.errstate(invalid="ignore"):
        # Flat enough: the two half-differences on each side agree (no jump between them).
        jump = np.maximum(np.linalg.norm((right - points) - (points - left), axis=-1),
                          np.linalg.norm((down - points) - (points - up), axis=-1))
        ok = np.isfinite(n).all(-1) & (norm[..., 0] > 0) & (jump < max_jump * dist)
    return np.where(ok[..., None], n, 0.0), ok


def depth_mesh(points: np.ndarray, step: int = 4, max_edge_frac: float = 0.05,
               centre: np.ndarray | None = None) -> trimesh.Trimesh:
    """The range image's surface as a triangle mesh (every step-th pixel), without the
    triangles that bridge a depth discontinuity (an edge longer than max_edge_frac of its
    distance from the camera)."""
    sub = points[::step, ::step]
    h, w, _ = sub.shape
    idx = np.arange(h * w).reshape(h, w)
    a, b, c, d = idx[:-1, :-1].ravel(), idx[:-1, 1:].ravel(), idx[1:, 1:].ravel(), idx[1:, :-1].ravel()
    faces = np.concatenate([np.stack([a, b, c], -1), np.stack([a, c, d], -1)])
    verts = sub.reshape(-1, 3)
    tri = verts[faces]
    ok = np.isfinite(tri).all(axis=(1, 2))
    if centre is not None:
        edge = np.max(np.linalg.norm(tri - np.roll(tri, 1, axis=1), axis=-1), axis=1)
        dist = np.linalg.norm(tri.mean(1) - centre, axis=-1)
        with np.errstate(invalid="ignore"):
            ok &= edge < max_edge_frac * dist + 1e-9
    faces = faces[ok]
    verts = np.where(np.isfinite(verts), verts, 0.0)
    return trimesh.Trimesh(verts, faces, process=False)


def load_receiver_mesh(spec, base_dir) -> trimesh.Trimesh:
    """The [receiver] mesh placed in the world: x = R(rotation_deg) (scale x_mesh) + position."""
    try:
        mesh = load_mesh(spec.mesh, base_dir)
    except Exception as exc:  # MeshError and trimesh's many
        raise ReceiverError(f"cannot use the receiver mesh: {exc}".splitlines()[0]) from exc
    v = float(spec.scale) * np.asarray(mesh.vertices) @ pose_matrix(spec.rotation_deg).T
    return trimesh.Trimesh(v + np.asarray(spec.position, np.float64), np.asarray(mesh.faces), process=False)


@dataclasses.dataclass(eq=False)
class ReceiverSurface:
    """One photo's receiver: kind "plane", "depth" (depth (H, W) z_cam metres) or "mesh"
    (mesh in world metres)."""

    kind: str = "plane"
    depth: np.ndarray | None = None
    mesh: trimesh.Trimesh | None = None
    _cache: dict = dataclasses.field(default_factory=dict, repr=False)

    def _depth_geometry(self, camera: PinholeCamera):
        if "depth" not in self._cache:
            pts = depth_points(self.depth, camera)
            nrm, ok = _depth_normals(pts, camera.centre)
            self._cache["depth"] = (pts, nrm, ok)
        return self._cache["depth"]

    def blocker_mesh(self, camera: PinholeCamera | None) -> trimesh.Trimesh | None:
        """The receiver as a mesh that hides sky and sun (None for the plane: rays going up
        from it never meet it)."""
        if self.kind == "mesh":
            return self.mesh
        if self.kind == "depth":
            if "blocker" not in self._cache:
                pts, _, _ = self._depth_geometry(camera)
                self._cache["blocker"] = depth_mesh(pts, centre=camera.centre)
            return self._cache["blocker"]
        return None

    def _surface(self, camera: PinholeCamera, cols: np.ndarray, rows: np.ndarray):
        """Points (N, 3), unit normals (N, 3) and validity (N,) at integer pixels."""
        n = len(cols)
        if self.kind == "depth":
            pts, nrm, ok = self._depth_geometry(camera)
            r = np.clip(np.rint(rows).astype(np.int64), 0, pts.shape[0] - 1)
            c = np.clip(np.rint(cols).astype(np.int64), 0, pts.shape[1] - 1)
            return pts[r, c], nrm[r, c], ok[r, c]
        if self.kind == "mesh":
            d = camera.pixel_rays(cols, rows)
            d /= np.linalg.norm(d, axis=1, keepdims=True)
            o = np.broadcast_to(camera.centre, d.shape)
            loc, iray, itri = self.mesh.ray.intersects_location(o, d, multiple_hits=False)
            pts = np.full((n, 3), np.nan)
            nrm = np.zeros((n, 3))
            ok = np.zeros(n, bool)
            pts[iray] = loc
            face_n = np.asarray(self.mesh.face_normals)[itri]
            flip = np.einsum("nj,nj->n", face_n, d[iray]) > 0  # face the camera
            face_n[flip] *= -1
            nrm[iray] = face_n
            ok[iray] = True
            return pts, nrm, ok
        pts, ok = camera.ground_points(cols, rows)
        nrm = np.zeros((n, 3))
        nrm[:, 2] = 1.0
        return pts, nrm, ok

    def at_pixels(self, view, cols, rows):
        """Receiver points (N, 3), unit normals (N, 3), valid (N,) and d(point)/d(col, row)
        (N, 3, 2) at pixels (col, row) of a PhotoView (a pinhole camera, or a top-down grid
        for the plane)."""
        cols = np.asarray(cols, dtype=np.float64).ravel()
        rows = np.asarray(rows, dtype=np.float64).ravel()
        if view.grid is not None:
            if self.kind != "plane":
                raise ReceiverError(f"a {self.kind} receiver needs a perspective camera, not a top-down map")
            pts, ok, jac2 = view.ground_of_pixels(cols, rows)
            nrm = np.zeros((len(cols), 3))
            nrm[:, 2] = 1.0
            return pts, nrm, ok, np.concatenate([jac2, np.zeros((len(cols), 1, 2))], axis=1)
        camera = view.camera
        pts, nrm, ok = self._surface(camera, cols, rows)
        # The tangent plane (point, normal) cut by the rays half a pixel away on each side.
        c = camera.centre
        jac = np.zeros((len(cols), 3, 2))
        for j, (dc, dr) in enumerate(((0.5, 0.0), (0.0, 0.5))):
            ends = []
            for sign in (1.0, -1.0):
                d = camera.pixel_rays(cols + sign * dc, rows + sign * dr)
                den = np.einsum("nj,nj->n", nrm, d)
                lam = np.einsum("nj,nj->n", nrm, np.nan_to_num(pts) - c) / np.where(np.abs(den) > 1e-12, den, 1e-12)
                ends.append(c + lam[:, None] * d)
                ok &= (np.abs(den) > 1e-9) & (lam > 0)
            jac[:, :, j] = ends[0] - ends[1]
        ok &= np.isfinite(pts).all(1) & np.isfinite(jac).all(axis=(1, 2))
        return np.where(ok[:, None], pts, 0.0), nrm, ok, np.where(ok[:, None, None], jac, 0.0)


def receiver_for_photo(scene, name: str, shape: tuple[int, int], meshes: dict) -> ReceiverSurface:
    """The receiver of photo ``name`` (shape (H, W)) from a SceneSpec; meshes caches loaded meshes.

    Raises ReceiverError with a one-line reason when it cannot be modelled.
    """
    spec = scene.receiver
    if spec.kind == "plane":
        return ReceiverSurface("plane")
    if spec.kind == "mesh":
        if "receiver" not in meshes:
            meshes["receiver"] = load_receiver_mesh(spec, scene.base_dir)
        return ReceiverSurface("mesh", mesh=meshes["receiver"])
    if spec.kind == "depth":
        own = scene.photo(name).depth
        file = own or spec.depth
        if not file:
            raise ReceiverError("no range image: give [receiver] depth or this photo's depth in scene.toml")
        base = Path(scene.base_dir) if scene.base_dir is not None else Path(".")
        depth = read_depth(base / file, shape)
        camera = scene.camera_for(name)
        if camera is not None and camera.kind == "explicit" and scene.object is not None:
            centre = -np.asarray(camera.R, float).T @ np.asarray(camera.t, float)
            _check_depth_scale(depth, Path(file).name, centre, scene.object.position)
        return ReceiverSurface("depth", depth=depth)
    raise ReceiverError(f"receiver kind {spec.kind!r} cannot be modelled")
