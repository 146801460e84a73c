"""A top-down photo folder rendered by the project's own model (the fitter's same-model test).

The pillar's soft shadow (disk profile) on a top-down map, each pixel the mean of
4 x 4 point samples (a sensor pixel integrates over its area), times a lit level of
0.6 plus Gaussian noise, written as a 16-bit linear PNG with its scene.toml. Used by
the fitter's tests and its noise benchmark (``softshadow bench --what fit``).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from scene import CameraSpec, ObjectSpec, PhotoSpec, SceneSpec, dump_scene
from softshadow import GroundGrid, Pose, ShadowParams, SoftShadowModel, Sun

__all__ = ["model_topdown_folder"]


def model_topdown_folder(folder, k: float = 0.012, rho: float = 0.25, noise: float = 0.004, seed: int = 0,
                         size: int = 192, sun: tuple[float, float] = (150.0, 40.0),
                         time: str | None = "2026-04-20T10:30:00+09:00", group: str = "10:30",
                         centre: tuple[float, float] = (-0.9, 1.6), extent_m: float = 2.6,
                         mesh=None) -> Path:
    """Write ``folder/top.png`` (size x size pixels over extent_m metres around centre (x, y), by
    default around the pillar's shadow under the default sun) and ``folder/scene.toml`` (sun
    azimuth/elevation in degrees given); returns the folder.

    k, rho: the shadow's range and brightness; noise: Gaussian sigma in linear units of full
    scale (the lit ground is 0.6); seed: the noise draw. mesh: a trimesh (world metres, on the
    ground) in place of the pillar, written as ``folder/object.ply``.
    """
    import cv2
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    # Point-sampled on a 4x finer grid and block-averaged (its own pixel footprint), and without
    # the sky the object hides: the data the same-model fits and their tests were made for.
    model = SoftShadowModel.from_mesh("pillar" if mesh is None else mesh, profile="disk", footprint=False,
                                      hidden_sky=False)
    if mesh is not None:
        mesh.export(folder / "object.ply")
    grid = GroundGrid.around(tuple(centre), extent_m, size)
    fine = GroundGrid.around(tuple(centre), extent_m, 4 * size)
    shading = np.asarray(model.ground_map(ShadowParams(k, rho), Sun(*sun), Pose(), fine))
    shading = shading.reshape(size, 4, size, 4).mean(axis=(1, 3))
    rng = np.random.default_rng(seed)
    img = np.clip(0.6 * shading + rng.normal(0, noise, shading.shape), 0, 1)
    cv2.imwrite(str(folder / "top.png"), np.rint(img * 65535).astype(np.uint16))
    dump_scene(SceneSpec(object=ObjectSpec("pillar" if mesh is None else "object.ply"), photos={"top.png": PhotoSpec(
        time=time, group=group, sun_azimuth_deg=sun[0], sun_elevation_deg=sun[1],
        camera=CameraSpec("topdown", pixel_m=grid.pixel_m, origin_m=grid.origin_m))}),
        folder / "scene.toml")
    return folder
