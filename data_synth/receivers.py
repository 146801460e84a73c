"""Receivers: the surface the shadow falls on (the ground plane, or a height field).

A receiver answers ``height(xy)`` and ``normal(xy)`` for world points and,
when it is not the plane z = 0, gives a triangle mesh for ray casting (it can
hide sky from itself and from the object). The height field stands in for a
range-sensor background (the seed's figures 19-24): a smooth procedural
terrain, so its shading uses analytic normals while rays hit its dense mesh.
"""

from __future__ import annotations

import dataclasses
from typing import Callable

import numpy as np
import trimesh

__all__ = ["PlaneReceiver", "HeightfieldReceiver", "bank_terrain"]


@dataclasses.dataclass(frozen=True)
class PlaneReceiver:
    """The ground plane z = 0 (normal +z)."""

    mesh: None = None

    def height(self, xy: np.ndarray) -> np.ndarray:
        """Heights (N,) of world points xy (N, 2)."""
        return np.zeros(len(xy))

    def normal(self, xy: np.ndarray) -> np.ndarray:
        """Unit normals (N, 3)."""
        out = np.zeros((len(xy), 3))
        out[:, 2] = 1.0
        return out

    def max_slope(self) -> float:
        return 0.0


@dataclasses.dataclass(frozen=True, eq=False)
class HeightfieldReceiver:
    """z = f(x, y) over a rectangle, with gradient grad(x, y) -> (df/dx, df/dy).

    bounds: (xmin, ymin, xmax, ymax) metres; spacing: mesh spacing in metres.
    Outside the rectangle the surface continues as f clamped to the border.
    """

    f: Callable[[np.ndarray, np.ndarray], np.ndarray]
    grad: Callable[[np.ndarray, np.ndarray], tuple[np.ndarray, np.ndarray]]
    bounds: tuple[float, float, float, float]
    spacing: float = 0.05
    mesh: trimesh.Trimesh = dataclasses.field(init=False)

    def __post_init__(self):
        x0, y0, x1, y1 = self.bounds
        xs = np.arange(x0, x1 + 0.5 * self.spacing, self.spacing)
        ys = np.arange(y0, y1 + 0.5 * self.spacing, self.spacing)
        gx, gy = np.meshgrid(xs, ys)
        verts = np.stack([gx.ravel(), gy.ravel(), self.f(gx, gy).ravel()], -1)
        nx = len(xs)
        i, j = np.meshgrid(np.arange(len(ys) - 1), np.arange(nx - 1), indexing="ij")
        a = (i * nx + j).ravel()
        b, c, d = a + 1, a + nx + 1, a + nx
        faces = np.concatenate([np.stack([a, b, c], -1), np.stack([a, c, d], -1)])  # +z facing
        object.__setattr__(self, "mesh", trimesh.Trimesh(verts, faces, process=False))

    def _clamp(self, xy):
        x0, y0, x1, y1 = self.bounds
        return np.clip(xy[:, 0], x0, x1), np.clip(xy[:, 1], y0, y1)

    def height(self, xy: np.ndarray) -> np.ndarray:
        x, y = self._clamp(np.asarray(xy, dtype=np.float64).reshape(-1, 2))
        return self.f(x, y)

    def normal(self, xy: np.ndarray) -> np.ndarray:
        x, y = self._clamp(np.asarray(xy, dtype=np.float64).reshape(-1, 2))
        fx, fy = self.grad(x, y)
        n = np.stack([-fx, -fy, np.ones_like(fx)], -1)
        return n / np.linalg.norm(n, axis=-1, keepdims=True)

    def max_slope(self) -> float:
        """Largest |grad f| on the mesh nodes (for the no-self-shadowing check)."""
        v = self.mesh.vertices
        fx, fy = self.grad(v[:, 0], v[:, 1])
        return float(np.max(np.hypot(fx, fy)))


def bank_terrain(bounds=(-4.0, -4.0, 4.0, 8.0), rise_m: float = 0.6, start_y: float = 0.9,
                 width_m: float = 1.6, bump_m: float = 0.04, spacing: float = 0.04) -> HeightfieldReceiver:
    """Flat ground that rises smoothly (a grassy bank) north of y = start_y, with gentle bumps.

    Height = rise * S((y - start_y) / width) + bump * sin(2.1 x) sin(1.7 y), S the
    smoothstep 3t^2 - 2t^3 on [0, 1]. The steepest slope is 1.5 rise / width + bumps.
    """
    def f(x, y):
        t = np.clip((y - start_y) / width_m, 0.0, 1.0)
        return rise_m * (3 * t ** 2 - 2 * t ** 3) + bump_m * np.sin(2.1 * x) * np.sin(1.7 * y) * (1 - 0.8 * t)

    def grad(x, y):
        t = np.clip((y - start_y) / width_m, 0.0, 1.0)
        inside = ((y - start_y) > 0) & ((y - start_y) < width_m)
        ds = np.where(inside, 6 * t * (1 - t) / width_m, 0.0)
        damp = 1 - 0.8 * t
        ddamp = np.where(inside, -0.8 / width_m, 0.0)
        fx = bump_m * 2.1 * np.cos(2.1 * x) * np.sin(1.7 * y) * damp
        fy = rise_m * ds + bump_m * np.sin(2.1 * x) * (1.7 * np.cos(1.7 * y) * damp + np.sin(1.7 * y) * ddamp)
        return fx, fy

    return HeightfieldReceiver(f, grad, tuple(bounds), spacing)
