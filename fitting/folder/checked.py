"""One group fitted and checked: the sun searched when it is not known, each photo checked against the
fit (``verdict.photo_check``), photos that do not fit left out and the group refitted."""

from __future__ import annotations

import dataclasses
import time as _time

from ..photos.grouping import PhotoGroup
from ..photos.views import PhotoView
from ..report.results import GroupResult
from ..solve.options import FitOptions
from ..solve.uncertainty import range_upper_bound
from ..verdict.photo_check import judge, photo_agreement

__all__ = ["fit_checked"]


def _fit_group_with_sun(model, pose, views, group: PhotoGroup, options: FitOptions, sky_model=None,
                        samples=None) -> GroupResult:
    """Fit a group; when the sun is unknown, search for it coarsely, then fit and re-plan.
    samples: the group's samples already drawn for these views (``fit_group``)."""
    from ..solve.group import fit_group  # with JAX (see groups.fit_groups)
    if all(v.sun_source != "fitted" for v in views):
        return fit_group(model, pose, views, group.label, group.time, options, sky_model, samples)
    from ..photos.sun_search import search_sun
    az, el, _ = search_sun(model, pose, views[0])
    for v in views:
        v.sun_azimuth_deg, v.sun_elevation_deg = az, el
    result = None
    for _ in range(3):  # re-plan around the refined sun
        result = fit_group(model, pose, views, group.label, group.time, options, sky_model)
        if not result.fitted:
            return result
        moved = abs(result.sun_azimuth_deg - views[0].sun_azimuth_deg) + abs(
            result.sun_elevation_deg - views[0].sun_elevation_deg)
        for v in views:
            v.sun_azimuth_deg, v.sun_elevation_deg = result.sun_azimuth_deg, result.sun_elevation_deg
        if moved < 0.05:
            break
    return result


def fit_checked(model, pose, views: list[PhotoView], group: PhotoGroup,
                 options: FitOptions, sky_model=None, samples=None) -> tuple[GroupResult, list[dict]]:
    """Fit a group, then check each photo against the fit (``photo_check``): a photo that does not
    fit is left out (a ``skipped`` entry naming the group and why) and the group refitted without
    it; a group where no photo shows a shadow gets "no shadow in view" and no values; a doubt that
    cannot be resolved makes the group unreliable, with a warning. samples: the samples already
    drawn for these views (``fitting.solve.lod``), used by the first fit."""
    start = _time.perf_counter()
    # The check reads the fit's profile data, which the fit builds only when plots are wanted; it
    # does not read the overlays, which are drawn only when plots are (0.4-0.5 s a group).
    checked = dataclasses.replace(options, plots=True, overlays=options.overlays if options.plots else "none")
    left_out: list[dict] = []
    while True:
        result = _fit_group_with_sun(model, pose, views, PhotoGroup(group.label, group.time,
                                                                    [v.name for v in views]), checked, sky_model,
                                     samples if not left_out else None)
        if not result.fitted:
            break
        verdict = judge(photo_agreement(result))
        if verdict.no_shadow:
            result = GroupResult(group.label, group.time, [v.name for v in views], error=verdict.no_shadow,
                                 warnings=result.warnings)
            break
        if verdict.leave_out and len(views) > 1:
            name, reason = verdict.leave_out[0]
            left_out.append({"photo": name, "reason": f"left out of group {group.label}: {reason}"})
            views = [v for v in views if v.name != name]
            continue
        if verdict.warnings:
            result.warnings += verdict.warnings
            result.reliable = False
        if verdict.range_unmeasured and result.identifiable and result.range_k is not None:
            # What hides the rho measurement hides the penumbra's width too: k is then a bound.
            result.identifiable = False
            result.range_k = range_upper_bound(result.range_k, result.range_stderr_stat or 0.0, result.penumbra_px,
                                               result.range_stderr)
            result.warnings.append(f"range not identifiable: {verdict.range_unmeasured}; range_k is an upper bound")
        break
    if result.fitted and result.identifiable and result.range_k is not None and result.range_k > options.range_k_max:
        # The samples' band and the start were sized for k up to range_k_max: beyond it the band
        # may cut the penumbra short.
        result.warnings.append(f"k = {result.range_k:.4g} is beyond range_k_max = {options.range_k_max:g}: the "
                               "samples may not cover the whole penumbra (raise --range-k-max)")
        result.reliable = False
    if left_out and result.fitted:
        result.warnings.append("refitted without " + ", ".join(s["photo"] for s in left_out)
                               + ", which did not fit the other photos (see skipped)")
    if not options.plots:
        result.plot_profiles, result.plot_overlays = [], []
    result.seconds = _time.perf_counter() - start
    return result, left_out


