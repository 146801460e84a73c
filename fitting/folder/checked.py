"""One group fitted and checked: the sun searched when it is not known, photos the rule book finds
out of place left out and the group refitted, a refit with the sun free when the model does not fit
(to name the cause), and the group judged with all of it (``fitting.verdict.rules``)."""

from __future__ import annotations

import dataclasses
import time as _time

from ..photos.grouping import PhotoGroup
from ..photos.views import PhotoView
from ..report.results import GroupResult
from ..solve.options import FitOptions
from ..verdict import rules
from ..verdict.evidence import GroupContext, LevelOfDetail, SunCheck

__all__ = ["fit_checked"]

_SUN_SETTLED_DEG = 0.05  # the re-planned sun moved less than this: the samples' band is where the sun is
_SUN_REPLANS = 12
#: A refit with the sun free only names a cause: the suns of a clock 12 minutes off or an object 5 %
#: too large settled within 3 re-plans, and a larger move is a cause found all the same.
_SUN_CHECK_REPLANS = 4


def _fit_group_with_sun(model, pose, views, group: PhotoGroup, options: FitOptions, sky_model=None,
                        fit_sun: bool | None = None, replans: int = _SUN_REPLANS,
                        samples=None) -> tuple[GroupResult, float | None]:
    """Fit a group; when its sun is fitted (unknown, or ``fit_sun``), re-plan the samples around the
    refined sun until it settles (an unknown sun is first searched for coarsely). ``views`` are
    changed in place (their sun). samples: the group's samples already drawn for these views
    (``fit_group``; used when the sun is not fitted). Returns the result and, for a fitted sun,
    its last move (degrees, azimuth plus elevation; None: the sun was not fitted)."""
    from softshadow import SunBelowHorizonError  # with JAX, as fit_group

    from ..solve.group import fit_group  # with JAX (see groups.fit_groups)
    if not fit_sun and all(v.sun_source != "fitted" for v in views):
        return fit_group(model, pose, views, group.label, group.time, options, sky_model, samples=samples), None
    if any(v.sun_source == "fitted" for v in views):
        from ..photos.sun_search import search_sun
        try:
            guess = search_sun(model, pose, views)
        except ValueError as exc:
            return GroupResult.failed(group.label, group.time, [v.name for v in views],
                                      f"cannot search for the sun: {exc}"), None
        for v in views:
            v.sun_azimuth_deg, v.sun_elevation_deg = guess.azimuth_deg, guess.elevation_deg
    result: GroupResult | None = None
    moved: float | None = None
    # Re-plan around the refined sun: each solve moves it by about 2 deg at the most, since the
    # samples' band is planned around the sun it starts from (a table2 sun searched 5 deg high took
    # 7 re-plans to settle; stopped after 3, it read k 1.7 times the truth).
    for _ in range(replans):
        try:
            result = fit_group(model, pose, views, group.label, group.time, options, sky_model, fit_sun=True)
        except SunBelowHorizonError as exc:
            # The free sun wandered below the horizon: no sun casts these shadows from this scene.
            return GroupResult.failed(group.label, group.time, [v.name for v in views], (
                f"no sun fits the shadows: the sun fitted from them went below the horizon "
                f"({str(exc).splitlines()[0]}); check the object and the cameras in scene.toml")), None
        if not result.fitted:
            return result, None
        moved = abs(result.sun_azimuth_deg - views[0].sun_azimuth_deg) + abs(
            result.sun_elevation_deg - views[0].sun_elevation_deg)
        for v in views:
            v.sun_azimuth_deg, v.sun_elevation_deg = result.sun_azimuth_deg, result.sun_elevation_deg
        if moved < _SUN_SETTLED_DEG:
            break
    assert result is not None  # replans >= 1
    return result, moved


def _sun_check(model, pose, views: list[PhotoView], group: PhotoGroup, options: FitOptions, sky_model,
               result: GroupResult, sun_path) -> SunCheck | None:
    """A refit with the sun free (copies of the views), as evidence of what a misfit comes from."""
    free = [dataclasses.replace(v) for v in views]
    refit, _ = _fit_group_with_sun(model, pose, free, group, dataclasses.replace(options, plots=False), sky_model,
                                   fit_sun=True, replans=_SUN_CHECK_REPLANS)
    if not refit.fitted or refit.evidence is None:
        return None
    return SunCheck(d_azimuth_deg=refit.sun_azimuth_deg - views[0].sun_azimuth_deg,
                    d_elevation_deg=refit.sun_elevation_deg - views[0].sun_elevation_deg,
                    misfit_before=rules.misfit_of(result.evidence), misfit_after=rules.misfit_of(refit.evidence),
                    k_after=refit.evidence.k, elevation_deg=float(views[0].sun_elevation_deg),
                    path_deg_per_min=sun_path, sun_given=views[0].sun_source == "given")


def fit_checked(model, pose, views: list[PhotoView], group: PhotoGroup, options: FitOptions, sky_model=None, *,
                level_of_detail: LevelOfDetail | None = None,
                sun_path: tuple[float, float] | None = None, samples=None,
                _band_widened_from: tuple[float, float] | None = None) -> tuple[GroupResult, list[dict]]:
    """Fit a group and judge it (``fitting.verdict.rules``): a photo the rules find out of place is
    left out (a ``skipped`` entry naming the group and why) and the group refitted without it; a
    group that shows no shadow gets "no shadow in view" and no values; a misfit is traced to its
    likely cause with a refit with the sun free. level_of_detail: the mesh level fitted (evidence);
    sun_path: the sun's daily motion at the group's time, (d azimuth, d elevation) in degrees per
    minute (None: not known); samples: the samples already drawn for these views
    (``fitting.solve.lod``), used by the first fit. A k beyond the samples' band on a scene the
    model fits is fitted again, once, with the band widened (``rules.wants_wider_band``)."""
    start = _time.perf_counter()
    level_of_detail = level_of_detail or LevelOfDetail()
    all_views = list(views)
    given = max(len(views), len(group.photos))
    left_out: list[tuple[str, str]] = []
    while True:
        result, sun_moved = _fit_group_with_sun(model, pose, views, PhotoGroup(group.label, group.time,
                                                                               [v.name for v in views]), options,
                                                sky_model, samples=samples if not left_out else None)
        if not result.fitted or result.evidence is None:
            break
        fit = result.evidence
        why = rules.no_shadow(fit)
        if why:
            result = GroupResult.failed(group.label, group.time, result.photos, why,
                                        [f"{p}: {r}" for p, r in fit.photos_without_shadow])
            break
        leave = rules.photo_to_leave_out(fit, GroupContext(given, tuple(left_out), level_of_detail))
        if leave is None:
            break
        left_out.append(leave)
        views = [v for v in views if v.name != leave[0]]
    if result.fitted and result.evidence is not None:
        context = GroupContext(given, tuple(left_out), level_of_detail, sun_last_move_deg=sun_moved,
                               band_widened_from=_band_widened_from)
        if rules.wants_sun_check(result.evidence):
            context = dataclasses.replace(context, sun_check=_sun_check(model, pose, views, group, options, sky_model,
                                                                        result, sun_path))
        if rules.wants_wider_band(result.evidence, context):
            wider = dataclasses.replace(options, range_k_max=rules.WIDER_BAND * options.range_k_max)
            # All the photos again: the wider band may keep a photo the first fit left out.
            refit, skipped = fit_checked(model, pose, all_views, group, wider, sky_model,
                                         level_of_detail=level_of_detail, sun_path=sun_path,
                                         _band_widened_from=(options.range_k_max, float(result.evidence.k)))
            seconds = _time.perf_counter() - start
            return dataclasses.replace(refit, diagnostics=dataclasses.replace(refit.diagnostics, seconds=seconds)), skipped
        estimate, verdict = rules.judge_fit(result.evidence, context)
        result = dataclasses.replace(result, estimate=estimate, verdict=verdict)
    diagnostics = dataclasses.replace(result.diagnostics, seconds=_time.perf_counter() - start,
                                      lod_faces=level_of_detail.faces, mesh_faces=level_of_detail.mesh_faces)
    result = dataclasses.replace(result, diagnostics=diagnostics)
    return result, [{"photo": name, "reason": f"left out of group {group.label}: {reason}"} for name, reason in left_out]
