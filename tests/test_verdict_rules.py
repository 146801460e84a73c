"""The rule book on typed evidence, without a fit (``fitting.verdict.rules`` and ``edge_rules``):
a shadow at all, the photos left out, goodness of fit and its likely cause, agreement between photos,
identifiability and its bound, the other flags, and a failed group."""

from __future__ import annotations

import dataclasses
import math

import pytest

from fitting.verdict import edge_rules, rules
from fitting.verdict.evidence import (EdgeEvidence, FitEvidence, GroupContext, LevelOfDetail, PhotoEvidence,
                                      SunCheck, SunFree)


def _photo(name="a.jpg", **kw) -> PhotoEvidence:
    """A photo that fits well (the numbers of a table2 photo at 640x480)."""
    base = dict(photo=name, n_samples=1300, n_lit=780, n_umbra=300, n_penumbra=80, rms=0.02, rms_lit=0.023,
                rms_umbra=0.005, rms_penumbra=0.02, noise_lit=0.022, noise_umbra=0.004, misfit=0.9,
                shadow_depth=0.84, predicted_depth=0.84, depth_gap=0.0, k=0.0057,
                k_stderr=0.0002, rho=0.159, rho_stderr=0.001)
    base.update(kw)
    return PhotoEvidence(**base)


def _fit(photos=None, **kw) -> FitEvidence:
    """A well-described three-photo group (k 0.0057, rho 0.159, a 2.3 px penumbra)."""
    base = dict(k=0.0057, rho=0.159, k_stderr_stat=0.00015, rho_stderr_stat=0.0006, k_stderr_sys=0.00047,
                rho_stderr_sys=0.002, penumbra_px=2.3, blur_px=0.7, n_in_penumbra=260, n_in_umbra=900,
                n_profiles=300, converged=True, range_k_max=0.03)
    base.update(kw)
    # By default the photos agree with the group's values.
    base["photos"] = tuple(photos) if photos is not None else tuple(
        _photo(f"{i}.jpg", k=base["k"], rho=base["rho"]) for i in range(3))
    return FitEvidence(**base)


# ---------------------------------------------------------------------------------- a clean group

def test_a_well_described_group_is_reliable_with_the_fits_values_and_no_warning():
    estimate, verdict = rules.judge_fit(_fit(), GroupContext(photos_given=3))
    assert verdict.reliable and verdict.identifiable and verdict.warnings == ()
    assert estimate.range_k == 0.0057 and estimate.rho == 0.159
    assert estimate.range_stderr == pytest.approx(math.hypot(0.00015, 0.00047))
    assert rules.photo_to_leave_out(_fit(), GroupContext(photos_given=3)) is None
    assert rules.no_shadow(_fit()) is None and not rules.wants_sun_check(_fit())


def test_a_failed_group_is_neither_reliable_nor_identifiable():
    from fitting.report.results import GroupResult
    verdict = rules.failed(["a.jpg: no shadow"])
    assert not verdict.reliable and not verdict.identifiable and verdict.warnings == ("a.jpg: no shadow",)
    g = GroupResult.failed("09:20", "09:20", ["a.jpg"], "fit failed: boom")
    data = g.to_json()
    assert data["reliable"] is False and data["identifiable"] is False and data["error"] == "fit failed: boom"
    # A kept record written before (reliable and identifiable beside an error) reads back as failed.
    old = dict(data, reliable=True, identifiable=True)
    again = GroupResult.from_json(old)
    assert not again.reliable and not again.identifiable
    with pytest.raises(ValueError):
        dataclasses.replace(g, verdict=dataclasses.replace(g.verdict, reliable=True))


# -------------------------------------------------------------------------------- a shadow at all

def test_no_shadow_when_no_photo_is_darker_or_the_fitted_shadow_is_too_shallow():
    gray = [_photo(f"{i}.jpg", shadow_depth=0.01) for i in range(3)]
    assert rules.no_shadow(_fit(gray)).startswith("no shadow in view: no photo is darker")
    # Three gray frames fitted as a group: rho 0.995, depths not measured (no umbra samples).
    flat = [_photo(f"{i}.jpg", shadow_depth=math.nan, n_umbra=3) for i in range(3)]
    why = rules.no_shadow(_fit(flat, rho=0.995))
    assert why.startswith("no shadow in view: the fitted umbra is 0.5 % darker") and "5 %" in why
    assert "3 %" in rules.no_shadow(_fit(rho=0.97))
    assert rules.no_shadow(_fit(rho=0.94)) is None


# ------------------------------------------------------------------------------ photos left out

def test_a_photo_without_the_shadow_the_others_show_is_left_out_even_among_two():
    cap = _photo("cap.jpg", shadow_depth=0.02)
    for photos in ([_photo("a.jpg"), _photo("b.jpg"), cap], [_photo("a.jpg"), cap]):
        name, reason = rules.photo_to_leave_out(_fit(photos), GroupContext(photos_given=len(photos)))
        assert name == "cap.jpg" and reason.startswith("no shadow edge where the model puts one")


def test_a_photo_that_shows_none_of_the_shadow_is_kept_but_counted():
    blind = [_photo("blind.jpg", n_umbra=4, n_penumbra=0, shadow_depth=math.nan),
             _photo("dim.jpg", n_umbra=1, n_penumbra=7, shadow_depth=math.nan)]
    fit = _fit([_photo("a.jpg")] + blind)
    assert rules.photo_to_leave_out(fit, GroupContext(photos_given=3)) is None
    _, verdict = rules.judge_fit(fit, GroupContext(photos_given=3))
    assert not verdict.reliable and any(w.startswith("only 1 of the group's 3 photos measured the shadow")
                                        for w in verdict.warnings)
    assert rules.judge_fit(_fit([_photo("a.jpg"), _photo("b.jpg"), blind[0]]), GroupContext(3))[1].reliable


def test_a_photo_that_misfits_alone_is_left_out_but_not_when_every_photo_misfits():
    off = _photo("off.jpg", misfit=6.0)
    name, reason = rules.photo_to_leave_out(_fit([_photo("a.jpg"), off, _photo("b.jpg")]), GroupContext(3))
    assert name == "off.jpg" and "camera registration or time off" in reason
    all_off = [_photo(f"{i}.jpg", misfit=m) for i, m in enumerate((3.1, 6.0, 3.4))]
    assert rules.photo_to_leave_out(_fit(all_off), GroupContext(3)) is None
    # A penumbra beyond the band: the whole group's fit is off, no photo is blamed.
    assert rules.photo_to_leave_out(_fit([_photo("a.jpg"), off, _photo("b.jpg")], k=0.05), GroupContext(3)) is None


def test_never_more_than_half_of_the_photos_are_left_out():
    off = _photo("off.jpg", misfit=6.0)
    fit = _fit([_photo("a.jpg"), off])
    assert rules.photo_to_leave_out(fit, GroupContext(photos_given=3, left_out=(("c.jpg", "r"),))) is None
    assert rules.photo_to_leave_out(fit, GroupContext(photos_given=2)) == ("off.jpg", rules.photo_to_leave_out(
        fit, GroupContext(photos_given=2))[1])


def test_an_umbra_with_two_levels_is_left_out_among_clean_ones_and_flags_a_group_of_one():
    two = _photo("two.jpg", rms_umbra=0.177, rms_lit=0.022)
    name, reason = rules.photo_to_leave_out(_fit([_photo("a.jpg"), two, _photo("b.jpg")]), GroupContext(3))
    assert name == "two.jpg" and reason.startswith("the umbra is not one level")
    _, verdict = rules.judge_fit(_fit([two]), GroupContext(1))
    assert not verdict.reliable and verdict.warnings[0].startswith("two.jpg: the umbra is not one level")
    # Small residuals are not flagged whatever their ratio, nor an umbra of few samples.
    for quiet in (_photo(rms_umbra=0.02, rms_lit=0.003), _photo(rms_umbra=0.177, n_umbra=5)):
        assert rules.judge_fit(_fit([quiet]), GroupContext(1))[1].reliable


def test_a_group_that_lost_most_of_its_photos_is_not_reliable():
    one = [_photo("a.jpg")]
    _, verdict = rules.judge_fit(_fit(one), GroupContext(photos_given=3, left_out=(("b.jpg", "x"), ("c.jpg", "y"))))
    assert not verdict.reliable and any(w.startswith("only 1 of the group's 3 photos") for w in verdict.warnings)
    assert any("refitted without b.jpg, c.jpg" in w for w in verdict.warnings)
    _, verdict = rules.judge_fit(_fit(one), GroupContext(photos_given=2, left_out=(("b.jpg", "x"),)))
    assert verdict.reliable  # a lens cap among two: the other photo stands


# ------------------------------------------------------------------------------ goodness of fit

def _misdescribed(**kw):
    return _fit([_photo(f"{i}.jpg", misfit=m) for i, m in enumerate((2.7, 3.8, 3.0))], **kw)


def test_a_misfit_in_every_photo_flags_the_group_bounds_k_and_names_the_scene():
    fit = _misdescribed(k=0.0107)
    assert rules.wants_sun_check(fit)
    estimate, verdict = rules.judge_fit(fit, GroupContext(3))
    assert not verdict.reliable and not verdict.identifiable and estimate.range_k > 0.0107
    (misfit,) = [w for w in verdict.warnings if w.startswith("the fitted shadow does not match the photos")]
    assert "3.0 times the noise" in misfit and "object's size or pose" in misfit
    assert not any("umbra is not one level" in w or "texture" in w for w in verdict.warnings)


@pytest.mark.parametrize("misfits, move_deg, reliable", [
    ((2.3, 2.6, 2.4), 0.03, True),  # the known sun stays: the penumbra's shape, not the scene
    ((2.3, 2.6, 2.4), 0.5, False),  # the sun follows the shadow: the scene is misdescribed
    ((6.0, 8.4, 7.0), 0.0, False),  # too far off to be the penumbra's shape alone
])
def test_a_misfit_that_a_free_sun_does_not_follow_is_the_penumbras_shape(misfits, move_deg, reliable):
    fit = _fit([_photo(f"{i}.jpg", misfit=m) for i, m in enumerate(misfits)],
               sun_free=SunFree(0.0, move_deg, 0.0057, 0.159, elevation_deg=50.0))
    estimate, verdict = rules.judge_fit(fit, GroupContext(3))
    assert verdict.reliable is reliable
    assert not verdict.identifiable and estimate.range_k > 0.0057  # k is a bound either way
    shape = any("penumbra's shape does not match" in w for w in verdict.warnings)
    misdescribed = any(w.startswith("the fitted shadow does not match the photos") for w in verdict.warnings)
    assert (shape, misdescribed) == (reliable, not reliable)
    # The wedge rule is named unless the fit already used it.
    assert any("--rule wedge" in w for w in verdict.warnings) is reliable
    on_steps = rules.judge_fit(dataclasses.replace(fit, receiver="mesh"), GroupContext(3))[1]
    assert any("--rule wedge" in w for w in on_steps.warnings) is reliable
    wedged = rules.judge_fit(dataclasses.replace(fit, rule="wedge", rule_asked="wedge"), GroupContext(3))[1]
    assert wedged.reliable is reliable and not any("--rule wedge" in w for w in wedged.warnings)


def test_a_rule_asked_for_and_not_used_is_said():
    fit = _fit(rule="edge", rule_asked="auto", rule_unavailable="IMG_1.jpg: its samples carry no normals")
    _, verdict = rules.judge_fit(fit, GroupContext(3))
    assert verdict.reliable  # a note, not a flag: the edge fit stands on its own
    assert ("fitted with the edge rule, not the auto rule asked for: IMG_1.jpg: its samples carry no normals"
            in verdict.warnings)
    assert not any("rule asked for" in w for w in rules.judge_fit(_fit(), GroupContext(3))[1].warnings)


def test_the_cause_of_a_misfit_from_a_refit_with_the_sun_free():
    fit = _misdescribed()
    # A clock 12 minutes fast: the refit moves the sun back along its path (09:20 in April, Iwate).
    path = (0.30, 0.15)  # degrees per minute in azimuth and elevation
    clock = SunCheck(-3.6 * math.cos(0), -1.8, 3.0, 1.1, 0.006, elevation_deg=51.0,
                     path_deg_per_min=path)
    clock = dataclasses.replace(clock, d_azimuth_deg=-12 * path[0], d_elevation_deg=-12 * path[1])
    text = " ".join(rules.judge_fit(fit, GroupContext(3, sun_check=clock))[1].warnings)
    assert "likely the clock" in text and "12 minutes earlier" in text
    # The object 5 % too large: the shadows fit a higher sun, barely moved in azimuth.
    size = SunCheck(0.2, 1.6, 3.0, 1.4, 0.006, elevation_deg=51.1, path_deg_per_min=path)
    text = " ".join(rules.judge_fit(fit, GroupContext(3, sun_check=size))[1].warnings)
    assert "likely the object's size" in text and "6 % smaller" in text
    # The same move with a sun given in scene.toml: that sun may be off.
    text = " ".join(rules.judge_fit(fit, GroupContext(3, sun_check=dataclasses.replace(size, sun_given=True)))[1].warnings)
    assert "likely the object's size" in text and "the sun given in scene.toml" in text
    # Moved across its path in azimuth: the sun, or the object's position (both move the shadow sideways).
    aside = SunCheck(-0.8, 0.2, 2.3, 1.6, 0.006, elevation_deg=19.5, path_deg_per_min=(0.02, 0.25))
    text = " ".join(rules.judge_fit(fit, GroupContext(3, sun_check=aside))[1].warnings)
    assert "likely the sun or the object's position" in text
    # A refit that does not fit either: not the sun.
    stuck = dataclasses.replace(size, misfit_after=2.9)
    text = " ".join(rules.judge_fit(fit, GroupContext(3, sun_check=stuck))[1].warnings)
    assert "object's size or pose" in text and "sun free did not fit either" in text


def test_k_beyond_the_band_is_the_clock_when_the_sun_explains_it_else_raise_the_band():
    fit = _fit(k=0.10)
    assert rules.wants_sun_check(fit)
    _, verdict = rules.judge_fit(fit, GroupContext(3))
    assert not verdict.reliable and any("raise --range-k-max" in w for w in verdict.warnings)
    clock = SunCheck(-3.7, 1.6, 1.9, 0.9, 0.006, elevation_deg=53.0, path_deg_per_min=(0.33, -0.14))
    _, verdict = rules.judge_fit(fit, GroupContext(3, sun_check=clock))
    assert not verdict.identifiable and any("beyond range_k_max" in w and "likely the clock" in w
                                            for w in verdict.warnings)
    assert not any("raise --range-k-max" in w for w in verdict.warnings)


def test_shadows_that_fit_another_sun_flag_the_group_with_the_cause():
    """A clock 7 minutes off on a rising bank: every photo fits (misfit 1.2-1.4, texture hides it), but
    the solve with the sun free moves the sun 1 deg; described right, it moves at most 0.12 deg."""
    still = _fit(sun_free=SunFree(0.02, -0.03, 0.0057, 0.159, elevation_deg=52.0))
    assert not rules.wants_sun_check(still) and rules.judge_fit(still, GroupContext(3))[1].reliable
    # A low sun over a narrow shadow: the sun moves, k and rho do not follow it.
    loose = _fit(sun_free=SunFree(0.1, -4.0, 0.0058, 0.159, elevation_deg=21.0))
    assert not rules.wants_sun_check(loose) and rules.judge_fit(loose, GroupContext(3))[1].reliable
    moved = _fit(k=0.027, sun_free=SunFree(-1.0, 0.76, 0.023, 0.159, elevation_deg=52.3))
    assert rules.wants_sun_check(moved) and rules.sun_moves(moved) == pytest.approx(1.0, abs=0.05)
    clock = SunCheck(-1.7, 1.4, 1.3, 1.2, 0.012, elevation_deg=52.3, path_deg_per_min=(-0.21, 0.17))
    estimate, verdict = rules.judge_fit(moved, GroupContext(3, sun_check=clock))
    assert not verdict.reliable and not verdict.identifiable and estimate.range_k > 0.027
    text = " ".join(verdict.warnings)
    assert "the shadows fit a sun 1.0 deg from the scene's, and k or rho follow it" in text and "likely the clock" in text


def test_a_sun_moved_far_that_k_follows_by_half_an_error_flags_the_group():
    """A ball over a bank described 9 % too large (calibration study, group 12): every photo fits
    (misfit 0.84), the solve with the sun free moves the known sun 0.81 deg and k follows it by 0.9 of
    its stated error: the shadows fit another sun. Following by less than half an error does not."""
    errors = dict(k=0.0276, rho=0.7965, k_stderr_stat=0.0030, k_stderr_sys=0.0022, rho_stderr_stat=0.0039,
                  penumbra_px=21.1, receiver="depth")
    k_err = math.hypot(0.0030, 0.0022)
    follows = _fit(**errors, sun_free=SunFree(-0.17, 0.80, 0.0276 - 0.9 * k_err, 0.7941, elevation_deg=56.6))
    assert rules.sun_moves(follows) == pytest.approx(0.81, abs=0.01) and rules.wants_sun_check(follows)
    assert not rules.judge_fit(follows, GroupContext(3))[1].reliable
    assert rules.SUN_FREE_SHIFT == 0.5
    barely = _fit(**errors, sun_free=SunFree(-0.17, 0.80, 0.0276 - 0.45 * k_err, 0.7955, elevation_deg=56.6))
    assert rules.sun_moves(barely) is None and rules.judge_fit(barely, GroupContext(3))[1].reliable


def test_a_refit_that_leaves_k_beyond_the_band_does_not_explain_it():
    """A penumbra under a pixel fitted far too wide (the hard-cases `subpixel` group): the refit with
    the sun free moves the sun but keeps k beyond the band, and the misfit was fine to begin with."""
    fit = _fit(k=0.063)
    moved = SunCheck(0.1, 2.9, 0.69, 0.7, 0.05, elevation_deg=55.0, path_deg_per_min=(0.25, 0.1))
    _, verdict = rules.judge_fit(fit, GroupContext(3, sun_check=moved))
    assert any("raise --range-k-max" in w for w in verdict.warnings)
    assert not any("likely" in w for w in verdict.warnings)


def test_the_texture_rule_is_averaged_across_a_wide_penumbra():
    """A faint shadow (rho 0.67) over asphalt: the lit residual 34 % of the depth, a 25 px penumbra."""
    rough = [_photo("a.jpg", rms_lit=0.112, shadow_depth=0.33, predicted_depth=0.33, k=0.018, rho=0.67)]
    assert rules.judge_fit(_fit(rough, k=0.018, rho=0.67, penumbra_px=25.5), GroupContext(1))[1].reliable
    _, verdict = rules.judge_fit(_fit(rough, k=0.018, rho=0.67, penumbra_px=2.6), GroupContext(1))
    assert not verdict.reliable and any("texture rivals the shadow" in w for w in verdict.warnings)


@pytest.mark.parametrize("rhos, reliable", [
    ((0.159, 0.159, 0.159), True),  # three views agree: rho stands
    ((0.159, 0.163, 0.155), False),  # they disagree by 2.8 errors each (Birge ratio 2.8): texture moved them
    ((0.159, 0.159, None), True),  # the third has too few umbra samples to measure rho: two views agree
    ((0.159,), False),  # one photo: nothing to compare
    ((0.159, None), False),  # one view measured rho on its own
])
def test_under_texture_rho_stands_when_independent_views_agree(rhos, reliable):
    photos = [_photo(f"{i}.jpg", rms_lit=0.3, rho=0.159 if r is None else r,
                     n_umbra=rules.MIN_PHOTO_UMBRA_SAMPLES - 1 if r is None else 300) for i, r in enumerate(rhos)]
    estimate, verdict = rules.judge_fit(_fit(photos), GroupContext(len(photos)))
    assert verdict.reliable is reliable
    assert not verdict.identifiable and estimate.range_k > 0.0057  # k stays a bound either way
    texture = [w for w in verdict.warnings if "texture rivals the shadow" in w]
    assert len(texture) == 1 and (("rho stands" in texture[0]) is reliable)


def test_a_forced_level_of_detail_that_moves_k_is_named():
    lod = LevelOfDetail(1000, 26600, forced=True, shift_k_se=2.0, shift_rho_se=7.1)
    _, verdict = rules.judge_fit(_fit(), GroupContext(3, level_of_detail=lod))
    assert not verdict.reliable and any("level of detail of 1,000" in w and "--lod auto" in w
                                        for w in verdict.warnings)
    fine = dataclasses.replace(lod, shift_k_se=0.05, shift_rho_se=0.08)
    assert rules.judge_fit(_fit(), GroupContext(3, level_of_detail=fine))[1].reliable


# ------------------------------------------------------------------------------------ agreement

def test_photos_that_disagree_widen_the_error_and_beyond_a_limit_flag_the_group():
    # table2 at 400x300, 13:21: one photo's sheet found, two not.
    photos = [_photo("a.jpg", rho=0.193, rho_stderr=0.0023), _photo("b.jpg", rho=0.243, rho_stderr=0.0129),
              _photo("c.jpg", rho=0.233, rho_stderr=0.0196)]
    estimate, verdict = rules.judge_fit(_fit(photos, rho=0.211, rho_stderr_stat=0.0057), GroupContext(3))
    assert verdict.reliable and estimate.rho_stderr > 0.03 and abs(estimate.rho - 0.190) < 2 * estimate.rho_stderr
    far = [_photo("a.jpg", rho=0.16, rho_stderr=0.001), _photo("b.jpg", rho=0.30, rho_stderr=0.001)]
    _, verdict = rules.judge_fit(_fit(far, rho=0.2), GroupContext(2))
    assert not verdict.reliable and any(w.startswith("the photos disagree on rho") for w in verdict.warnings)
    # Photos that disagree on k flag the group, unless no photo resolves the penumbra (calibration
    # study group 90: 0.0025 +- 0.0002 against 0.056 +- 0.003 for a 1 px penumbra): k is then a bound.
    on_k = [_photo("a.jpg", k=0.0025, k_stderr=0.0002), _photo("b.jpg", k=0.056, k_stderr=0.003)]
    _, verdict = rules.judge_fit(_fit(on_k, k=0.0027, k_stderr_stat=0.0002), GroupContext(2))
    assert not verdict.reliable and any(w.startswith("the photos disagree on k") for w in verdict.warnings)
    estimate, verdict = rules.judge_fit(_fit(on_k, k=0.0027, k_stderr_stat=0.0002, penumbra_px=1.0), GroupContext(2))
    assert verdict.reliable and not verdict.identifiable and estimate.range_k > 0.0027
    assert not any("the photos disagree on k" in w for w in verdict.warnings)
    # Photos without umbra samples are not compared on rho.
    blind = [_photo("a.jpg"), _photo("b.jpg", rho=0.8, rho_stderr=0.001, n_umbra=4)]
    estimate, _ = rules.judge_fit(_fit(blind), GroupContext(2))
    assert estimate.rho_stderr == pytest.approx(math.hypot(0.0006, 0.002))


# ----------------------------------------------------------------------- identifiability and rest

def test_identifiable_when_the_penumbra_is_resolved_and_k_is_measured():
    estimate, verdict = rules.judge_fit(_fit(k=0.01, k_stderr_stat=0.001, penumbra_px=3.0), GroupContext(3))
    assert verdict.identifiable and estimate.range_k == 0.01


@pytest.mark.parametrize("k, se, pen, upper", [
    (0.01, 0.001, 0.5, 0.01 / 0.5),            # penumbra under a pixel: k at one pixel's width
    (0.01, 0.004, 0.4, max(0.018, 0.01 / 0.4)),
    (0.01, 0.006, 3.0, 0.01 + 2 * 0.006),      # k lost in its own noise: k + 2 sigma
    (0.002, 0.0005, None, 0.002 + 2 * 0.0005),  # no sample inside the penumbra
])
def test_not_identifiable_gives_an_upper_bound_and_a_warning(k, se, pen, upper):
    # No camera blur: the blur spot (0.58 px) bounds k below these bounds.
    estimate, verdict = rules.judge_fit(_fit(k=k, k_stderr_stat=se, k_stderr_sys=0.0, penumbra_px=pen, blur_px=0.0),
                                        GroupContext(3))
    assert not verdict.identifiable
    assert estimate.range_k == pytest.approx(upper) and estimate.range_k >= k
    assert any("upper bound" in w for w in verdict.warnings)


@pytest.mark.parametrize("pen, per_k", [(0.3, None), (None, 380.0), (0.114, 380.0)])
def test_a_penumbra_under_the_blur_spot_bounds_k_by_the_spots_width(pen, per_k):
    """A fit that traded k for blur (k near 0, a penumbra far under the spot, or none sampled at all)
    bounds k by the k whose penumbra would fill the blur spot, from the width per unit k at the outline
    (given, or the fitted width over the fitted k): a knot at 752x564 read k 1e-7 for a truth of
    0.0036 (a 1.37 px penumbra under a 1.39 px spot), and the bound of 0.0000 was a confident miss."""
    k, blur = 3e-4, 0.63
    estimate, verdict = rules.judge_fit(_fit(k=k, k_stderr_stat=1e-5, k_stderr_sys=0.0, penumbra_px=pen,
                                             blur_px=blur, n_in_penumbra=0 if pen is None else 40,
                                             no_ramp_k=1e-5 if pen is None else None, penumbra_px_per_k=per_k),
                                        GroupContext(3))
    spot = rules.RESOLVED_BLUR_WIDTHS * math.sqrt(1 / 12 + blur ** 2)
    width_per_k = per_k if per_k is not None else pen / k
    assert not verdict.identifiable
    assert estimate.range_k == pytest.approx(spot / width_per_k)
    assert rules.unresolved_k(_fit(k=k, penumbra_px=pen, blur_px=blur, penumbra_px_per_k=per_k)) == pytest.approx(
        spot / width_per_k)
    assert math.isnan(rules.unresolved_k(_fit(k=k, penumbra_px=None, blur_px=blur)))
    # A resolved penumbra keeps its measured k: the spot bounds only what the photos do not resolve.
    estimate, verdict = rules.judge_fit(_fit(penumbra_px_per_k=per_k or 400.0), GroupContext(3))
    assert verdict.identifiable and estimate.range_k == 0.0057


def test_identifiability_thresholds():
    k = 0.01
    ident = lambda **kw: rules.judge_fit(_fit(**{"k": k, "k_stderr_stat": 0.001, "blur_px": 0.0, **kw}),
                                         GroupContext(3))[1].identifiable
    # The blur spot without blur: the pixel's area, 3 sqrt(1/12) = 0.87 px.
    spot = rules.RESOLVED_BLUR_WIDTHS * math.sqrt(1 / 12)
    assert ident(penumbra_px=spot * 1.001)
    assert not ident(penumbra_px=spot * 0.999)
    assert not rules.judge_fit(_fit(k=k, k_stderr_stat=0.001, blur_px=0.5, penumbra_px=spot * 1.001),
                               GroupContext(3))[1].identifiable  # a blurred photo's spot is wider
    assert ident(k_stderr_stat=rules.MAX_K_REL_STDERR * k, penumbra_px=2.0)
    assert not ident(k_stderr_stat=rules.MAX_K_REL_STDERR * k * 1.01, penumbra_px=2.0)


def test_too_few_samples_inside_a_narrow_penumbra_make_k_an_upper_bound():
    narrow = 0.99 * rules.NARROW_PENUMBRA_PX
    # A sharp camera (0.3 px of blur, a 1.25 px spot) resolves a penumbra under NARROW_PENUMBRA_PX.
    judge = lambda n, px=narrow: rules.judge_fit(_fit(k=0.01, k_stderr_stat=0.001, k_stderr_sys=0.002, blur_px=0.3,
                                                      penumbra_px=px, n_in_penumbra=n), GroupContext(3))
    assert judge(rules.MIN_PENUMBRA_SAMPLES)[1].identifiable
    estimate, verdict = judge(rules.MIN_PENUMBRA_SAMPLES - 1)
    assert not verdict.identifiable and estimate.range_k == pytest.approx(0.01 + 2 * math.hypot(0.001, 0.002))
    assert any(f"only {rules.MIN_PENUMBRA_SAMPLES - 1} samples" in w and "upper bound" in w for w in verdict.warnings)
    assert judge(3, rules.NARROW_PENUMBRA_PX)[1].identifiable  # wider than a blur spot: few samples suffice
    assert any("under the photo's blur spot" in w for w in judge(3, 0.5)[1].warnings)
    assert any("narrower than the resolution" in w for w in judge(0, None)[1].warnings)


def test_no_ramp_k_raises_the_bound_when_no_sample_is_inside_the_penumbra():
    estimate, _ = rules.judge_fit(_fit(k=5e-4, k_stderr_stat=1e-5, k_stderr_sys=0.0, penumbra_px=None,
                                       n_in_penumbra=0, no_ramp_k=0.0085), GroupContext(3))
    assert estimate.range_k == 0.0085


def test_a_fitted_sun_that_had_not_settled_makes_k_an_upper_bound_and_keeps_rho():
    estimate, verdict = rules.judge_fit(_fit(sun_fitted=True), GroupContext(3, sun_last_move_deg=2.1))
    assert not verdict.identifiable and verdict.reliable and estimate.range_k > 0.0057
    assert any("fitted sun had not settled" in w for w in verdict.warnings)
    assert rules.judge_fit(_fit(sun_fitted=True), GroupContext(3, sun_last_move_deg=0.04))[1].identifiable


def test_the_other_flags():
    flags = {
        "rho not measured": dict(n_in_umbra=rules.MIN_UMBRA_SAMPLES - 1),
        "only 9 shadow-edge profiles": dict(n_profiles=9),
        "the solver stopped before converging": dict(converged=False),
        "the ground's texture rivals the shadow": dict(photos=[_photo("a.jpg", rms_lit=0.3)]),
    }
    for text, kw in flags.items():
        _, verdict = rules.judge_fit(_fit(**kw), GroupContext(3))
        assert not verdict.reliable and any(text in w for w in verdict.warnings), text
    assert rules.judge_fit(_fit(n_in_umbra=rules.MIN_UMBRA_SAMPLES), GroupContext(3))[1].reliable
    # A solver stopped on its step limit whose next step would move k and rho by little has settled.
    assert rules.judge_fit(_fit(converged=False, remaining_step_se=0.05), GroupContext(3))[1].reliable
    _, verdict = rules.judge_fit(_fit(converged=False, remaining_step_se=0.5), GroupContext(3))
    assert not verdict.reliable and verdict.warnings == (
        "the solver stopped before converging (one more step would move k or rho by 0.5 of their errors)",)
    # A penumbra under the blur spot makes k a bound on the ground (the group stays reliable); on
    # steps or a bank the group is unreliable.
    estimate, verdict = rules.judge_fit(_fit(penumbra_px=1.3, blur_px=0.7), GroupContext(3))
    assert verdict.reliable and not verdict.identifiable and estimate.range_k > 0.0057
    assert any("the penumbra is under the photo's blur spot; range_k is an upper bound" in w
               for w in verdict.warnings)
    assert rules.judge_fit(_fit(penumbra_px=2.3, blur_px=0.7), GroupContext(3))[1].identifiable  # the spot: 2.27 px
    assert rules.judge_fit(_fit(penumbra_px=3.0, blur_px=0.7, receiver="depth"), GroupContext(3))[1].reliable


@pytest.mark.parametrize("rms_umbra, n_umbra, reliable", [(0.004, 300, True), (0.008, 300, False), (0.004, 3, False)])
def test_a_penumbra_under_the_blur_spot_on_relief_flags_the_group_when_its_umbra_is_not_one_level(
        rms_umbra, n_umbra, reliable):
    """On steps or a bank, a penumbra under the blur spot leaves k a bound; rho is trusted only when the
    umbra is fitted as one level at its noise (RMS over robust spread <= RELIEF_UMBRA_BIAS_RATIO)."""
    photos = [_photo(f"{i}.jpg", rms_umbra=rms_umbra, noise_umbra=0.004, n_umbra=n_umbra) for i in range(3)]
    estimate, verdict = rules.judge_fit(_fit(photos, penumbra_px=1.3, blur_px=0.7, receiver="mesh"), GroupContext(3))
    assert verdict.reliable is reliable and not verdict.identifiable and estimate.range_k > 0.0057
    relief = [w for w in verdict.warnings if "on a mesh receiver, whose relief shares its pixels" in w]
    assert bool(relief) is not reliable
    if rms_umbra > 0.004:
        assert "(the umbra's residual 2.00 times its noise)" in relief[0]
    # On the plane the same group is reliable, with k a bound.
    assert rules.judge_fit(_fit(photos, penumbra_px=1.3, blur_px=0.7), GroupContext(3))[1].reliable


@pytest.mark.parametrize("gap, reliable", [(0.06, False), (-0.06, True), (0.03, True), (-0.03, True)])
def test_a_photos_shadow_deeper_than_the_fitted_one_flags_the_group(gap, reliable):
    """Deeper: the fitted umbra holds partly lit pixels. Shallower (light the relief sends into the
    umbra) is no flag."""
    photos = [_photo(f"{i}.jpg", depth_gap=gap) for i in range(3)]
    _, verdict = rules.judge_fit(_fit(photos), GroupContext(3))
    assert verdict.reliable is reliable and verdict.identifiable
    assert any("the photos' shadow is 6.0 % of the lit level deeper than the fitted one" in w
               for w in verdict.warnings) is (not reliable)
    # The photos' median decides: one photo's gap alone does not.
    one = [photos[0], *[_photo(f"{i}.jpg") for i in (1, 2)]]
    assert rules.judge_fit(_fit(one), GroupContext(3))[1].reliable


# ----------------------------------------------------------------------------- without geometry

def _edges(**kw) -> EdgeEvidence:
    base = dict(modes=((math.log(0.2), 40),), measured_log=math.log(0.2), n_kept=40, n_structures=2,
                outlines=((math.log(0.2), 30), (math.log(0.21), 10)), dark_side_regions=(38,))
    base.update(kw)
    return EdgeEvidence(**base)


def test_edge_rules():
    assert edge_rules.judge_edges(_edges()) == edge_rules.judge_edges(_edges()) and edge_rules.judge_edges(
        _edges()).reliable
    cases = {
        "edges disagree: measured rho 0.200 (40 profiles), another mode at rho 0.300 (20 profiles)":
            dict(modes=((math.log(0.2), 40), (math.log(0.3), 20))),
        "only 6 shadow-edge profiles": dict(n_kept=6, outlines=((math.log(0.2), 6),), n_structures=1),
        "12 profiles spread over 8 separate structures": dict(n_kept=12, n_structures=8, outlines=()),
        "shadow outlines disagree": dict(outlines=((math.log(0.2), 20), (math.log(0.3), 20))),
        "dark sides scattered": dict(dark_side_regions=(1, 1, 2, 1, 1)),
    }
    for text, kw in cases.items():
        verdict = edge_rules.judge_edges(_edges(**kw))
        assert not verdict.reliable and any(w.startswith(text) for w in verdict.warnings), (text, verdict.warnings)
    # A second mode too small to count, a few stray dark sides, small outlines: no warning.
    assert edge_rules.judge_edges(_edges(modes=((math.log(0.2), 40), (math.log(0.3), 5)))).reliable
    assert edge_rules.judge_edges(_edges(dark_side_regions=(6, 1, 1, 1))).reliable
    assert edge_rules.judge_edges(_edges(outlines=((math.log(0.2), 37), (math.log(0.4), 3)))).reliable


def test_k_beyond_the_band_on_a_scene_that_fits_asks_for_a_wider_band_once():
    beyond = _fit(k=0.033, penumbra_px=12.0)
    assert rules.wants_wider_band(beyond, GroupContext(3))
    assert not rules.wants_wider_band(_fit(), GroupContext(3))  # k within the band
    # Once widened, never again; a scene the model does not fit, or whose sun explains k, is not refitted.
    assert not rules.wants_wider_band(beyond, GroupContext(3, band_widened_from=(0.03, 0.033)))
    misfit = _fit(k=0.033, penumbra_px=12.0, photos=[_photo(f"{i}.jpg", misfit=3.0) for i in range(3)])
    assert not rules.wants_wider_band(misfit, GroupContext(3))
    explained = SunCheck(d_azimuth_deg=2.0, d_elevation_deg=0.5, misfit_before=1.0, misfit_after=0.9, k_after=0.01)
    assert not rules.wants_wider_band(beyond, GroupContext(3, sun_check=explained))
    # The refit's verdict names what happened, as a note.
    widened = _fit(k=0.033, penumbra_px=12.0, range_k_max=0.06)
    _, verdict = rules.judge_fit(widened, GroupContext(3, band_widened_from=(0.03, 0.0331)))
    assert verdict.reliable and verdict.warnings == (
        "k read 0.0331, beyond the band of k <= 0.03 the samples were planned for: refitted with the band "
        "widened to 0.06",)
