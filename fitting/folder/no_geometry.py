"""A photo without geometry (no ``[object]``): its shadow edges measured on their own, as one group."""

from __future__ import annotations

import time as _time

import numpy as np

from scene import SceneSpec

from ..photos.read import Photo
from ..report.results import GroupResult
from ..solve.uncertainty import edge_rho_errors, profile_spread

__all__ = ["measure_without_scene"]


def measure_without_scene(photo: Photo, when, scene: SceneSpec | None) -> GroupResult:
    from ..edges.measure import measure_shadow_edges
    start = _time.perf_counter()
    label = photo.name
    time_label = when.strftime("%H:%M") if when is not None else None
    result = GroupResult(label=label, time=time_label, photos=[photo.name])
    pixel_m = None
    if scene is not None and scene.camera is not None and scene.camera.kind == "topdown":
        pixel_m = scene.camera.pixel_m
    m = measure_shadow_edges(photo.gray, mask=photo.excluded, pixel_m=pixel_m, linear_rgb=photo.linear)
    result.seconds = _time.perf_counter() - start
    if not m.edges_found:
        result.error = m.reason or "no shadow edge found"
        return result
    kept_log_rho = np.log([p.rho for p in m.profiles if p.kept])
    errors = edge_rho_errors(m.rho, m.rho_stderr, profile_spread(kept_log_rho))
    result.rho, result.rho_stderr = float(m.rho), errors.rho_stderr
    result.rho_stderr_stat, result.rho_stderr_sys = errors.rho_stderr_stat, errors.rho_stderr_sys
    result.penumbra_px, result.penumbra_px_iqr = float(m.penumbra_px), float(m.penumbra_px_iqr)
    result.penumbra_m = None if m.penumbra_m is None else float(m.penumbra_m)
    result.n_profiles = int(m.n_profiles)
    result.converged = True
    result.identifiable = True
    result.warnings, result.reliable = list(m.warnings), bool(m.reliable)
    return result


