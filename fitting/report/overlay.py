"""The fitted shadow over a (downsampled) photo, for the overlay plot.

One plan for the image's ground points (NumPy) and one compiled evaluation of
alpha at the points in its penumbra bands (JAX, in chunks of one fixed size so
that every photo shares one compilation); no gradients are needed here, so nothing is
assembled with JAX's eager ops.
"""

from __future__ import annotations

import numpy as np

from softshadow import GroundGrid, PinholeCamera, Pose, SoftShadowModel, Sun
from softshadow.internal import PointPlan, object_mask, plan_alpha_jit

__all__ = ["fitted_alpha_image"]

CHUNK = 16384  # band points per compiled evaluation


def fitted_alpha_image(model: SoftShadowModel, pose: Pose, sun: Sun, range_k: float,
                       view: PinholeCamera | GroundGrid) -> np.ndarray:
    """Alpha (H, W) of the model with ``range_k`` seen by ``view`` (a camera or a top-down
    grid); NaN where the pixel sees no ground or the object itself."""
    h, w = view.height, view.width
    rows, cols = np.mgrid[0:h, 0:w]
    if isinstance(view, GroundGrid):
        ground, valid = view.to_world(cols.ravel(), rows.ravel()), np.ones(h * w, bool)
    else:
        ground, valid = view.ground_points(cols.ravel(), rows.ravel())
    use = valid & ~object_mask(model.occluder, pose, view).ravel()
    alpha = np.full(h * w, np.nan)
    if not use.any():
        return alpha.reshape(h, w)
    points = ground[use]
    fine = view.pixel_m if isinstance(view, GroundGrid) else view.fine_footprint_m(ground, valid, use)
    pixel_m = max(fine, 1e-4)
    plan = model.plan_points(sun, pose, points, range_k_max=max(range_k, 1e-4), pixel_m=pixel_m)
    # Outside the penumbra bands alpha is the hard shadow; only band points go to JAX.
    values = np.asarray(plan.hard)[:len(points)].astype(np.float64)
    band = np.flatnonzero(np.asarray(plan.active)[:len(points)])
    # Fixed-size chunks: one compiled evaluation serves every photo and band size.
    for start in range(0, len(band), CHUNK):
        idx = band[start:start + CHUNK]
        take = lambda x, fill: np.concatenate(
            [np.asarray(x)[idx], np.full((CHUNK - len(idx),) + np.shape(x)[1:], fill, np.asarray(x).dtype)])
        chunk_plan = PointPlan(plan.edges, take(plan.edge_id, 0), take(plan.hard, 0.0),
                               take(plan.active, False), take(plan.near_boundary, 0.0))
        values[idx] = np.asarray(plan_alpha_jit(take(points, 0.0), chunk_plan, pose, sun,
                                                np.float64(range_k), model.rule,
                                                model.profile))[:len(idx)]
    alpha[use] = values
    return alpha.reshape(h, w)
