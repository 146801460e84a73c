"""Ordinary photos: the ground region, cast-shadow cues, honest confidence and user ignore masks.

A street-like photo is drawn analytically (fast): blue sky with white clouds
and a facade above the horizon, gravel below, a person's and a pole's long
shadows whose penumbra widens from the contact point (2 -> 60 px), lit by a
white sun and a blue sky (so the umbra is bluer), optionally an asphalt kerb
(an albedo edge, not a shadow). Sizes are chosen so that the photo is reduced
by 2 for measurement.
"""

from __future__ import annotations

import numpy as np
import pytest
from PIL import Image
from scipy import ndimage

from fitting.edges.measure import measure_shadow_edges
from fitting.edges.ground_region import ground_region
from fitting.photos.ignore_masks import IgnoreMaskError, ignore_mask_path, is_auxiliary, read_ignore_mask
from fitting.photos.read import list_photos
from fitting.edges.cues import bluer_umbrae, edge_evidence, log_rho_modes, mode_of_log_rho
from fitting.verdict.edge_rules import judge_edges

LUMA = np.array([0.2126, 0.7152, 0.0722])
SUN = np.array([1.0, 0.97, 0.9])
SKY_RHO = 0.22


def street_photo(h=840, w=1120, seed=0, kerb=False):
    """(linear rgb (h, w, 3), alpha (h, w), horizon row, true rho of the luminance)."""
    rng = np.random.default_rng(seed)
    hor = int(0.38 * h)
    pebbles = sum(ndimage.gaussian_filter(rng.normal(size=(h, w)), s) * s for s in (0.7, 2.0, 4.0))
    gravel = np.exp(0.3 * pebbles / pebbles.std())[..., None] * np.array([0.55, 0.5, 0.42])
    yy, xx = np.mgrid[0:h, 0:w].astype(float)
    d = np.array([-0.55, -0.83]) / np.hypot(0.55, 0.83)
    n = np.array([-d[1], d[0]])
    alpha = np.zeros((h, w))
    for cu, cv, half, length, grow in ((0.65 * w, 0.9 * h, 0.03 * w, 0.45 * w, 50.0),
                                       (0.2 * w, 0.87 * h, 0.008 * w, 0.4 * w, 35.0)):
        rel_u, rel_v = xx - cu, yy - cv
        along, across = rel_u * d[0] + rel_v * d[1], rel_u * n[0] + rel_v * n[1]
        dist = np.maximum(np.abs(across) - half, np.maximum(-along, along - length))
        width = 2.0 + grow * np.clip(along / length, 0.0, 1.0)
        alpha = np.maximum(alpha, np.clip(0.5 - dist / width, 0.0, 1.0))
    sky_light = SKY_RHO * np.array([0.8, 0.95, 1.4]) / 0.97
    irradiance = SUN * (1.0 - alpha[..., None]) + sky_light
    ground = gravel * irradiance
    if kerb:
        asphalt = np.exp(0.12 * ndimage.gaussian_filter(rng.normal(size=(h, w)), 0.7) * 2)[..., None] * 0.3
        ground = np.where((yy > 0.75 * h + 0.1 * xx)[..., None], asphalt * irradiance, ground)
    sky = np.stack([0.35 + 0.2 * yy / hor, 0.5 + 0.2 * yy / hor, 0.95 + 0.0 * yy], -1)
    cloud = ndimage.gaussian_filter(rng.normal(size=(h, w)), 15)
    cloud = np.clip((cloud / cloud.std() - 0.3) * 1.5, 0.0, 1.0)[..., None]
    sky = sky * (1.0 - cloud) + 1.2 * cloud
    facade = (yy > hor - 0.2 * h) & (yy <= hor) & (xx > 0.1 * w) & (xx < 0.75 * w)
    wall = np.full((h, w, 3), 0.45) * np.where(((xx // 40) % 2 == 0) & ((yy // 35) % 2 == 0), 0.3, 1.0)[..., None]
    wall = wall * np.where(xx < 0.35 * w, 0.3, 1.0)[..., None]
    above = np.where(facade[..., None], wall, sky)
    img = 0.6 * np.where((yy > hor)[..., None], ground, above)
    img = img * (1.0 + 0.01 * rng.normal(size=img.shape))
    rho = float((sky_light @ LUMA) / ((SUN + sky_light) @ LUMA))
    return np.clip(img, 0.0, 1.0), alpha, hor, rho


@pytest.fixture(scope="module")
def street():
    return street_photo()


# ----------------------------------------------------------------------------- the ground region

def test_ground_region_finds_the_sky_and_keeps_the_ground_below_the_horizon(street):
    img, _, hor, _ = street
    region = ground_region(img, img @ LUMA)
    assert region.sky_found
    assert abs(region.horizon_row - hor) < 0.05 * img.shape[0]
    assert not region.ground[: hor - 5].any()          # clouds and the facade are out
    assert region.ground[int(hor + 0.05 * img.shape[0]):].all()


def test_ground_region_of_a_photo_of_the_ground_only_is_everything():
    rng = np.random.default_rng(1)
    grey_ground = 0.3 * np.exp(0.2 * rng.normal(size=(200, 260)))
    for rgb in (None, np.repeat(grey_ground[..., None], 3, axis=2)):
        region = ground_region(rgb, grey_ground)
        assert not region.sky_found and region.horizon_row is None and region.ground.all()


# ----------------------------------------------------------------------------- the measurement

def test_wide_penumbra_shadows_on_gravel_under_clouds_are_measured_on_the_ground(street):
    img, alpha, hor, rho = street
    m = measure_shadow_edges(img @ LUMA, linear_rgb=img, saturation_level=1.0)
    assert m.edges_found
    kept = [p for p in m.profiles if p.kept]
    assert all(p.position_uv[1] > hor for p in kept)
    on_shadow = [p for p in kept if 0.0 < alpha[int(round(p.position_uv[1])), int(round(p.position_uv[0]))] < 1.0]
    assert len(on_shadow) >= 0.8 * len(kept)
    assert abs(m.rho - rho) < 0.03, (m.rho, rho, m.warnings)
    assert any(p.reject_reason and p.reject_reason.startswith("not on the ground") for p in m.profiles) or \
        not any(p.position_uv[1] < hor for p in m.profiles)


def test_a_kerb_beside_the_shadow_is_either_left_out_or_flagged():
    img, _, _, rho = street_photo(h=540, w=720, seed=3, kerb=True)
    m = measure_shadow_edges(img @ LUMA, linear_rgb=img, saturation_level=1.0)
    assert m.edges_found
    assert abs(m.rho - rho) < 0.03 or not m.reliable, (m.rho, rho, m.warnings)
    assert m.reliable == (not m.warnings)


# ----------------------------------------------------------------------------- cues and confidence

def reliability(shadow_like_log_rho, positions, shape, lowest_log, kept_log_rho=None):
    """(warnings, reliable) of the rule book on a measurement's cues; without ``kept_log_rho`` every
    kept profile has one step (its outlines agree)."""
    positions = np.asarray(positions, float).reshape(-1, 2)
    kept = np.zeros(len(positions)) if kept_log_rho is None else kept_log_rho
    verdict = judge_edges(edge_evidence(shadow_like_log_rho, positions, shape, lowest_log, kept, None))
    return list(verdict.warnings), verdict.reliable


def test_bluer_umbrae_apply_only_when_enough_edges_are_bluer():
    assert bluer_umbrae(np.array([0.5, 0.4, 0.02, 0.3, 0.6, 0.45, 0.0])).tolist() == [
        True, True, False, True, True, True, False]
    assert bluer_umbrae(np.array([0.5, 0.4, 0.0, 0.0, 0.0])) is None       # too few: a gray sky
    assert bluer_umbrae(np.full(8, np.nan)) is None                        # no colour


def test_two_well_filled_modes_make_the_measurement_unreliable():
    rng = np.random.default_rng(0)
    one = np.log(0.2) + 0.03 * rng.normal(size=40)
    two = np.log(0.55) + 0.03 * rng.normal(size=30)
    modes = log_rho_modes(np.concatenate([one, two]), np.log(0.005))
    assert len(modes) == 2 and abs(np.exp(modes[0][0]) - 0.2) < 0.02 and abs(np.exp(modes[1][0]) - 0.55) < 0.05
    line = np.stack([np.linspace(100, 600, 40), np.full(40, 500.0)], axis=1)
    warnings, reliable = reliability(np.concatenate([one, two]), line, (800, 1000), np.log(0.005))
    assert not reliable and warnings[0].startswith("edges disagree")
    warnings, reliable = reliability(np.concatenate([one, two[:5]]), line, (800, 1000), np.log(0.005))
    assert reliable and warnings == []


def test_edges_disagree_names_the_measured_mode_first_even_when_it_holds_fewer_profiles():
    """A tight mode (the shadows, 30 profiles) is denser than a spread one (a kerb, 45 profiles):
    the measurement takes the densest mode, and the warning must name that one as measured."""
    rng = np.random.default_rng(1)
    tight = np.log(0.2) + 0.01 * rng.normal(size=30)
    spread = np.log(0.5) + 0.08 * rng.normal(size=45)
    log_rho = np.concatenate([tight, spread])
    measured = np.exp(mode_of_log_rho(log_rho, np.log(0.005)))
    assert abs(measured - 0.2) < 0.01
    line = np.stack([np.linspace(100, 600, 75), np.full(75, 500.0)], axis=1)
    warnings, reliable = reliability(log_rho, line, (800, 1000), np.log(0.005))
    assert not reliable
    assert warnings[0].startswith(f"edges disagree: measured rho {measured:.3f} (")
    assert "another mode at rho 0.4" in warnings[0] or "another mode at rho 0.5" in warnings[0]


def test_few_profiles_on_scattered_structures_are_unreliable():
    rng = np.random.default_rng(0)
    scattered = rng.uniform(0, 1000, size=(12, 2))
    warnings, reliable = reliability(np.full(12, np.log(0.2)), scattered, (1000, 1000), np.log(0.005))
    assert not reliable and any("separate structures" in w for w in warnings)
    warnings, reliable = reliability(np.full(6, np.log(0.2)), scattered[:6], (1000, 1000), np.log(0.005))
    assert not reliable and any(w.startswith("only 6") for w in warnings)


def test_separate_outlines_with_different_steps_make_the_measurement_unreliable():
    """A kerb's long outline at 0.27 beside two shadow outlines at 0.32 (the street preset's seeds 7 and 10):
    each outline is consistent, and they are within one mode, but one of them is not a shadow."""
    rng = np.random.default_rng(1)
    kerb = np.stack([np.linspace(100, 300, 25), np.full(25, 700.0)], axis=1)
    shadow_a = np.stack([np.full(20, 600.0), np.linspace(100, 300, 20)], axis=1)
    shadow_b = np.stack([np.linspace(700, 900, 20), np.full(20, 300.0)], axis=1)
    specks = np.array([[50.0, 50.0], [52.0, 50.0], [54.0, 50.0], [56.0, 50.0]])   # a small outline, far off
    positions = np.concatenate([kerb, shadow_a, shadow_b])
    log_rho = np.concatenate([np.log(0.27) + 0.02 * rng.normal(size=25), np.log(0.32) + 0.02 * rng.normal(size=40)])
    warnings, reliable = reliability(log_rho, positions, (1000, 1000), np.log(0.005), log_rho)
    assert not reliable and any(w.startswith("shadow outlines disagree") for w in warnings)
    # the same outlines all at one step agree; a small outline (under a fifth of the profiles) far off is not compared
    same = np.concatenate([np.log(0.32) + 0.02 * rng.normal(size=65), np.log(0.2) * np.ones(4)])
    warnings, reliable = reliability(same, np.concatenate([positions, specks]), (1000, 1000), np.log(0.005), same)
    assert not any(w.startswith("shadow outlines disagree") for w in warnings)


def test_an_outline_whose_texture_changes_across_it_is_two_materials():
    """Per profile the texture ratio is noisy (a kerb's ranged 1.7-7); the outline's median decides."""
    from fitting.edges.cues import textured_outlines

    labels = np.array([1] * 6 + [2] * 6 + [3] * 2 + [4] * 3)
    ratios = np.array([3.1, 1.7, 6.9, 2.4, 4.0, np.nan,       # a kerb: median 3.1, x sqrt(0.27) = 1.6
                       0.5, 1.0, 1.9, 0.8, 1.2, 1.0,           # a shadow on one surface: median 1
                       5.0, 6.0,                               # too few to judge
                       2.9, 3.0, 3.1])                         # a dark shadow on smooth ground: noise, 1 / sqrt(rho)
    rho = np.array([0.27] * 14 + [0.11] * 3)
    assert textured_outlines(ratios, rho, labels).tolist() == [True] * 6 + [False] * 11


# ----------------------------------------------------------------------------- ignore masks

def _write_png(path, array):
    Image.fromarray(array).save(path)


def test_ignore_masks_are_auxiliary_files_not_photos(tmp_path):
    _write_png(tmp_path / "a.png", np.zeros((20, 30, 3), np.uint8))
    _write_png(tmp_path / "a.ignore.png", np.zeros((20, 30), np.uint8))
    (tmp_path / "b.depth.npy").write_bytes(b"")
    photos, skipped = list_photos(tmp_path)
    assert [p.name for p in photos] == ["a.png"] and skipped == []
    assert is_auxiliary("X.IGNORE.PNG") and is_auxiliary("x.depth.png") and not is_auxiliary("x.png")
    assert ignore_mask_path(tmp_path / "a.png") == tmp_path / "a.ignore.png"


def test_ignore_mask_reading_sizes_and_errors(tmp_path):
    mask = np.zeros((20, 30, 4), np.uint8)
    mask[2, 3, 3] = 255                                   # alpha alone counts
    _write_png(tmp_path / "m.png", mask)
    full = read_ignore_mask(tmp_path / "m.png", (20, 30))
    assert full.sum() == 1 and full[2, 3]
    half = read_ignore_mask(tmp_path / "m.png", (10, 15))
    assert half.sum() == 1 and half[1, 1]
    with pytest.raises(IgnoreMaskError, match=r"m.png: ignore mask is 30x20 px, the photo is 40x25 px"):
        read_ignore_mask(tmp_path / "m.png", (25, 40))

    class Scene:
        @staticmethod
        def photo(name):
            return type("P", (), {"ignore": "missing.png"})()
    with pytest.raises(IgnoreMaskError, match="missing.png: ignore mask named in scene.toml for a.png not found"):
        ignore_mask_path(tmp_path / "a.png", Scene())


def test_an_ignore_mask_beside_the_photo_removes_a_decoy_shadow(tmp_path):
    """Two shadows of different depth: the mask over the darker one leaves the other's rho."""
    from fitting.folder.api import fit_folder
    from fitting.photos.read import linear_to_srgb
    rng = np.random.default_rng(2)
    h, w = 160, 220
    yy, xx = np.mgrid[0:h, 0:w]
    ground = 0.5 * np.exp(0.1 * ndimage.gaussian_filter(rng.normal(size=(h, w)), 0.8) * 2)
    shade = np.ones((h, w))
    left = ndimage.gaussian_filter(((xx > 20) & (xx < 95) & (yy > 30) & (yy < 130)).astype(float), 1.5)
    right = ndimage.gaussian_filter(((xx > 125) & (xx < 200) & (yy > 30) & (yy < 130)).astype(float), 1.5)
    shade = shade - 0.7 * left - 0.88 * right               # rho 0.30 and 0.12
    lin = np.clip(ground * shade, 0, 1)
    srgb = np.rint(255 * linear_to_srgb(np.repeat(lin[..., None], 3, axis=2))).astype(np.uint8)
    _write_png(tmp_path / "p.png", srgb)
    mask = np.zeros((h, w), np.uint8)
    mask[:, 110:] = 255
    _write_png(tmp_path / "p.ignore.png", mask)
    res = fit_folder(tmp_path)
    (group,) = res.groups
    assert group.rho is not None and abs(group.rho - 0.30) < 0.03, group
