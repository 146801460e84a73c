"""A photo without geometry (no ``[object]``): its shadow edges measured on their own, as one group."""

from __future__ import annotations

import time as _time

import numpy as np

from scene import SceneSpec

from ..photos.read import Photo
from ..report.results import Estimate, FitDiagnostics, GroupResult
from ..solve.uncertainty import edge_rho_errors, profile_spread

__all__ = ["measure_without_scene"]


def measure_without_scene(photo: Photo, when, scene: SceneSpec | None) -> GroupResult:
    """The photo's shadow edges measured alone (``fitting.edges.measure``), judged by the rule book
    (``fitting.verdict.edge_rules``, through the measurement's verdict)."""
    from ..edges.measure import measure_shadow_edges
    start = _time.perf_counter()
    time_label = when.strftime("%H:%M") if when is not None else None
    pixel_m = None
    if scene is not None and scene.camera is not None and scene.camera.kind == "topdown":
        pixel_m = scene.camera.pixel_m
    m = measure_shadow_edges(photo.gray, mask=photo.excluded, pixel_m=pixel_m, linear_rgb=photo.linear)
    seconds = _time.perf_counter() - start
    if not m.edges_found:
        return GroupResult.failed(photo.name, time_label, [photo.name], m.reason or "no shadow edge found",
                                  diagnostics=FitDiagnostics(seconds=seconds))
    kept_log_rho = np.log([p.rho for p in m.profiles if p.kept])
    errors = edge_rho_errors(m.rho, m.rho_stderr, profile_spread(kept_log_rho))
    estimate = Estimate(rho=float(m.rho), rho_stderr=errors.rho_stderr, rho_stderr_stat=errors.rho_stderr_stat,
                        rho_stderr_sys=errors.rho_stderr_sys)
    diagnostics = FitDiagnostics(n_profiles=int(m.n_profiles), converged=True, penumbra_px=float(m.penumbra_px),
                                 penumbra_px_iqr=float(m.penumbra_px_iqr),
                                 penumbra_m=None if m.penumbra_m is None else float(m.penumbra_m), seconds=seconds)
    return GroupResult(photo.name, time_label, [photo.name], m.verdict, estimate, diagnostics=diagnostics)
