"""Parameter pytrees: the shadow's two parameters, the sun, and the object's pose.

Each is an ``equinox.Module`` so it can be differentiated, vmapped and passed
through ``jax.jit``; fields are JAX scalars or arrays in the units named.
"""

from __future__ import annotations

import equinox as eqx
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from .sun import light_direction

__all__ = ["ShadowParams", "Sun", "Pose", "rotation_matrix_xyz", "rotation_matrix_xyz_np",
           "range_to_paper", "brightness_to_paper", "paper_to_range_k", "paper_to_rho"]


class ShadowParams(eqx.Module):
    """The model's two parameters.

    range_k: range of the soft shadow k >= 0 (dimensionless; ``range`` = 100 k).
    rho: brightness of the shadow, umbra over lit irradiance, in (0, 1].
    """

    range_k: Float[Array, ""]
    rho: Float[Array, ""]

    def __init__(self, range_k=0.01, rho=0.3):
        self.range_k = jnp.asarray(range_k, dtype=jnp.result_type(float))
        self.rho = jnp.asarray(rho, dtype=jnp.result_type(float))


class Sun(eqx.Module):
    """Sun position in degrees: azimuth clockwise from north, elevation above the horizon."""

    azimuth_deg: Float[Array, ""]
    elevation_deg: Float[Array, ""]

    def __init__(self, azimuth_deg=180.0, elevation_deg=45.0):
        self.azimuth_deg = jnp.asarray(azimuth_deg, dtype=jnp.result_type(float))
        self.elevation_deg = jnp.asarray(elevation_deg, dtype=jnp.result_type(float))

    @property
    def light(self) -> Float[Array, "3"]:
        """Direction the light travels, L = -s, shape (3,)."""
        return light_direction(self.azimuth_deg, self.elevation_deg)

    @property
    def light_np(self) -> np.ndarray:
        """``light`` in NumPy float64, for the discrete steps (no eager JAX ops)."""
        return light_direction(float(self.azimuth_deg), float(self.elevation_deg), np)


def _rotation_xyz(rotation_deg, xp):
    """Rz @ Ry @ Rx for XYZ Euler angles in degrees, in the array module ``xp``."""
    rx, ry, rz = xp.deg2rad(xp.asarray(rotation_deg))
    cx, sx, cy, sy, cz, sz = xp.cos(rx), xp.sin(rx), xp.cos(ry), xp.sin(ry), xp.cos(rz), xp.sin(rz)
    one, zero = xp.ones_like(cx), xp.zeros_like(cx)
    Rx = xp.stack([xp.stack([one, zero, zero]), xp.stack([zero, cx, -sx]), xp.stack([zero, sx, cx])])
    Ry = xp.stack([xp.stack([cy, zero, sy]), xp.stack([zero, one, zero]), xp.stack([-sy, zero, cy])])
    Rz = xp.stack([xp.stack([cz, -sz, zero]), xp.stack([sz, cz, zero]), xp.stack([zero, zero, one])])
    return Rz @ Ry @ Rx


def rotation_matrix_xyz(rotation_deg) -> Float[Array, "3 3"]:
    """Rotation for XYZ Euler angles in degrees: about x, then y, then z (fixed axes).

    Equal to scipy's ``Rotation.from_euler("xyz", angles, degrees=True)``.
    """
    return _rotation_xyz(rotation_deg, jnp)


def rotation_matrix_xyz_np(rotation_deg) -> np.ndarray:
    """``rotation_matrix_xyz`` in NumPy float64, for the discrete steps (no eager JAX ops)."""
    return _rotation_xyz(np.asarray(rotation_deg, dtype=np.float64), np)


class Pose(eqx.Module):
    """Where the mesh goes: x_world = R(rotation_deg) (scale x_mesh) + position (metres)."""

    position: Float[Array, "3"]
    rotation_deg: Float[Array, "3"]
    scale: Float[Array, ""]

    def __init__(self, position=(0.0, 0.0, 0.0), rotation_deg=(0.0, 0.0, 0.0), scale=1.0):
        dtype = jnp.result_type(float)
        self.position = jnp.asarray(position, dtype=dtype).reshape(3)
        self.rotation_deg = jnp.asarray(rotation_deg, dtype=dtype).reshape(3)
        self.scale = jnp.asarray(scale, dtype=dtype)

    @property
    def rotation(self) -> Float[Array, "3 3"]:
        return rotation_matrix_xyz(self.rotation_deg)

    def apply(self, points: Float[Array, "*n 3"]) -> Float[Array, "*n 3"]:
        """Mesh-frame points to world points."""
        return (self.scale * points) @ self.rotation.T + self.position

    def apply_direction(self, vectors: Float[Array, "*n 3"]) -> Float[Array, "*n 3"]:
        """Rotate mesh-frame directions (normals) into the world."""
        return vectors @ self.rotation.T


def range_to_paper(range_k):
    """Paper units of the range of the soft shadow: 100 k."""
    return 100.0 * range_k


def brightness_to_paper(rho):
    """Paper units of the brightness: 255 rho^(1/2.2) (lit = 255)."""
    return 255.0 * rho ** (1.0 / 2.2)


def paper_to_range_k(range_paper):
    return range_paper / 100.0


def paper_to_rho(brightness_paper):
    return (brightness_paper / 255.0) ** 2.2
