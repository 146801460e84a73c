"""Parameter pytrees: the shadow's two parameters, the sun, and the object's pose.

Each is an ``equinox.Module`` so it can be differentiated, vmapped and passed
through ``jax.jit``; fields are scalars or arrays in the units named. Built from
plain numbers they hold NumPy arrays in JAX's current float type, so building
one dispatches no JAX operation (the discrete steps read them as they are);
built from JAX arrays or tracers (inside ``jax.grad``) they keep those.
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jax.scipy.spatial.transform import Rotation
from jaxtyping import Array, Float

from .sun import light_direction

__all__ = ["ShadowParams", "Sun", "Pose", "rotation_matrix_xyz"]


def _leaf(value, shape=()):
    """A parameter leaf: JAX arrays and tracers kept as JAX, anything else as NumPy."""
    dtype = jnp.result_type(float)  # a dtype lookup, not an operation
    if isinstance(value, jax.Array):
        return jnp.asarray(value, dtype=dtype).reshape(shape)
    return np.asarray(value, dtype=dtype).reshape(shape)


class ShadowParams(eqx.Module):
    """The model's two parameters.

    range_k: range of the soft shadow k >= 0 (dimensionless; ``range`` = 100 k).
    rho: brightness of the shadow, umbra over lit irradiance, in (0, 1].
    """

    range_k: Float[Array, ""]
    rho: Float[Array, ""]

    def __init__(self, range_k=0.01, rho=0.3):
        self.range_k = _leaf(range_k)
        self.rho = _leaf(rho)


class Sun(eqx.Module):
    """Sun position in degrees: azimuth clockwise from north, elevation above the horizon."""

    azimuth_deg: Float[Array, ""]
    elevation_deg: Float[Array, ""]

    def __init__(self, azimuth_deg=180.0, elevation_deg=45.0):
        self.azimuth_deg = _leaf(azimuth_deg)
        self.elevation_deg = _leaf(elevation_deg)

    @property
    def light(self) -> Float[Array, "3"]:
        """Direction the light travels, L = -s, shape (3,)."""
        return jnp.asarray(light_direction(self.azimuth_deg, self.elevation_deg))

    @property
    def light_np(self) -> np.ndarray:
        """``light`` in NumPy float64, for the discrete steps (no eager JAX ops)."""
        return np.asarray(light_direction(float(self.azimuth_deg), float(self.elevation_deg), np))


def rotation_matrix_xyz(rotation_deg) -> Float[Array, "3 3"]:
    """Rotation for XYZ Euler angles in degrees: about x, then y, then z (fixed axes), i.e.
    Rz @ Ry @ Rx, as scipy's ``Rotation.from_euler("xyz", angles, degrees=True)`` (JAX,
    differentiable; ``softshadow.posed.pose_matrix`` is the NumPy twin for discrete steps)."""
    return Rotation.from_euler("xyz", jnp.asarray(rotation_deg), degrees=True).as_matrix()


class Pose(eqx.Module):
    """Where the mesh goes: x_world = R(rotation_deg) (scale x_mesh) + position (metres)."""

    position: Float[Array, "3"]
    rotation_deg: Float[Array, "3"]
    scale: Float[Array, ""]

    def __init__(self, position=(0.0, 0.0, 0.0), rotation_deg=(0.0, 0.0, 0.0), scale=1.0):
        self.position = _leaf(position, (3,))
        self.rotation_deg = _leaf(rotation_deg, (3,))
        self.scale = _leaf(scale)

    @property
    def rotation(self) -> Float[Array, "3 3"]:
        return rotation_matrix_xyz(self.rotation_deg)

    def apply(self, points: Float[Array, "*n 3"]) -> Float[Array, "*n 3"]:
        """Mesh-frame points to world points."""
        return (self.scale * points) @ self.rotation.T + self.position

    def apply_direction(self, vectors: Float[Array, "*n 3"]) -> Float[Array, "*n 3"]:
        """Rotate mesh-frame directions (normals) into the world."""
        return vectors @ self.rotation.T
