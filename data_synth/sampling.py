"""Stratified sample patterns on the unit square, the unit disk, the sun's cap and the hemisphere.

All functions are pure NumPy over arrays. Stratification keeps the error of
a visibility estimate near an edge at about sqrt(strata cut by the edge) / N
instead of sqrt(N) / N.
"""

from __future__ import annotations

import numpy as np

__all__ = ["stratified_square", "concentric_disk", "orthonormal_basis", "cap_directions",
           "cosine_hemisphere_directions", "strata_side"]


def strata_side(n_samples: int) -> int:
    """Side m of the m x m stratification used for ``n_samples`` (rounded up to a square)."""
    if n_samples < 1:
        raise ValueError(f"need at least one sample, got {n_samples}")
    return int(np.ceil(np.sqrt(n_samples)))


def stratified_square(n_points: int, side: int, rng: np.random.Generator | None,
                      dtype=np.float64) -> np.ndarray:
    """Jittered stratified samples, shape (n_points, side*side, 2) in [0, 1)^2.

    rng None: the centre of every stratum (a fixed pattern, no noise, used where a
    spatially coherent estimate is better than an unbiased noisy one).
    """
    j, i = np.meshgrid(np.arange(side), np.arange(side), indexing="ij")
    base = np.stack([i.ravel(), j.ravel()], -1).astype(dtype)
    if rng is None:
        return np.broadcast_to((base + 0.5) / side, (n_points, side * side, 2))
    jitter = rng.random((n_points, side * side, 2), dtype=dtype)
    return (base[None] + jitter) / side


def concentric_disk(u: np.ndarray) -> np.ndarray:
    """Shirley-Chiu map of the unit square (..., 2) to the unit disk (..., 2), area-preserving."""
    a = 2.0 * u[..., 0] - 1.0
    b = 2.0 * u[..., 1] - 1.0
    use_a = np.abs(a) > np.abs(b)
    safe_a = np.where(a == 0, 1.0, a)
    safe_b = np.where(b == 0, 1.0, b)
    r = np.where(use_a, a, b)
    phi = np.where(use_a, (np.pi / 4) * (b / safe_a), (np.pi / 2) - (np.pi / 4) * (a / safe_b))
    phi = np.where((a == 0) & (b == 0), 0.0, phi)
    return np.stack([r * np.cos(phi), r * np.sin(phi)], -1)


def orthonormal_basis(n: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Two unit tangents (..., 3) completing unit normals n (..., 3) (Duff et al. 2017)."""
    x, y, z = n[..., 0], n[..., 1], n[..., 2]
    sign = np.where(z >= 0, 1.0, -1.0)
    a = -1.0 / (sign + z)
    b = x * y * a
    t1 = np.stack([1.0 + sign * x * x * a, sign * b, -sign * x], -1)
    t2 = np.stack([b, sign + y * y * a, -y], -1)
    return t1, t2


def cap_directions(axis: np.ndarray, radius_rad: float, u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Directions uniform in solid angle on the cap of half-angle ``radius_rad`` around ``axis`` (3,).

    u (..., 2) unit-square samples (stratification is kept by the concentric map).
    Returns (directions (..., 3), fractional disk radius (...,) in [0, 1]).
    """
    d = concentric_disk(u)
    rho2 = np.sum(d * d, -1)
    cos_t = 1.0 - rho2 * (1.0 - np.cos(radius_rad))
    sin_t = np.sqrt(np.clip(1.0 - cos_t * cos_t, 0.0, None))
    rho = np.sqrt(rho2)
    safe = np.where(rho > 0, rho, 1.0)
    cphi, sphi = d[..., 0] / safe, d[..., 1] / safe
    t1, t2 = orthonormal_basis(np.asarray(axis, dtype=np.float64))
    dirs = (cos_t[..., None] * axis + (sin_t * cphi)[..., None] * t1 + (sin_t * sphi)[..., None] * t2)
    # Fractional radius on the disk in angle, for limb darkening.
    frac = np.arccos(np.clip(cos_t, -1.0, 1.0)) / radius_rad
    return dirs, np.clip(frac, 0.0, 1.0)


def cosine_hemisphere_directions(normals: np.ndarray, u: np.ndarray) -> np.ndarray:
    """Cosine-weighted directions (P, N, 3) around unit normals (P, 3) from u (P, N, 2) (Malley)."""
    d = concentric_disk(u)
    z = np.sqrt(np.clip(1.0 - np.sum(d * d, -1), 0.0, None))
    t1, t2 = orthonormal_basis(normals)
    return (d[..., 0:1] * t1[:, None, :] + d[..., 1:2] * t2[:, None, :] + z[..., None] * normals[:, None, :])


def bilinear(image: np.ndarray, rows: np.ndarray, cols: np.ndarray, wrap: bool = False,
             fill: float | None = None) -> np.ndarray:
    """Bilinear samples of image (H, W[, C]) at fractional (rows, cols) (N,), via cv2.remap.

    Pixel (r, c) holds the value at (r, c). wrap: the image tiles the plane;
    fill: value outside the image (None: the nearest edge value).
    """
    import cv2

    img = np.ascontiguousarray(image, dtype=np.float32)
    n = len(rows)
    if wrap:
        h, w = img.shape[:2]
        rows = np.mod(rows, h)
        cols = np.mod(cols, w)
    block = 4096  # remap wants maps under 32767 a side: fold the point list into rows of 4096
    m = max(block, -(-n // block) * block)
    mx = np.zeros(m, np.float32)
    my = np.zeros(m, np.float32)
    mx[:n] = cols
    my[:n] = rows
    if wrap:
        border, value = cv2.BORDER_WRAP, 0.0
    elif fill is None:
        border, value = cv2.BORDER_REPLICATE, 0.0
    else:
        border, value = cv2.BORDER_CONSTANT, float(fill)
    out = cv2.remap(img, mx.reshape(-1, block), my.reshape(-1, block), cv2.INTER_LINEAR,
                    borderMode=border, borderValue=value)
    return out.reshape((m,) + img.shape[2:])[:n]
