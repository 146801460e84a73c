"""Confident answers that are right: each case that once came back confidently wrong comes back right
(the truth within two stated errors; an upper bound at or above it) or flagged with a warning that
names the likely cause (``fitting.verdict.rules``).

Physical table2 folders at 640x480 (seed 53) and 400x300 (seed 0, the demo's), rendered at the default
quality as the cases were found, and the dragon at 400x300; each case fits only the groups it needs.
"""

from __future__ import annotations

import datetime as dt
import json
import shutil
from pathlib import Path

import numpy as np
import pytest

def _synth(root: Path, preset: str, seed: int, size) -> Path:
    from data_synth import synthesize
    return synthesize(root / f"{preset}-{seed}-{size[0]}", preset, seed=seed, size=size, progress=False)


@pytest.fixture(scope="module")
def table2_640(tmp_path_factory) -> Path:
    return _synth(tmp_path_factory.mktemp("cases"), "table2", 53, (640, 480))


@pytest.fixture(scope="module")
def table2_400(tmp_path_factory) -> Path:
    return _synth(tmp_path_factory.mktemp("cases"), "table2", 0, (400, 300))


def _truth(folder: Path) -> dict:
    return {g["label"][:2]: g for g in json.loads((folder / "truth.json").read_text())["groups"]}


def _copy(src: Path, dst: Path, photos, edit=None) -> Path:
    """``photos`` of a folder with its scene.toml (``edit`` changes its dict) and truth.json."""
    import tomli_w
    import tomllib
    dst.mkdir(parents=True)
    for name in photos:
        shutil.copy(src / name, dst / name)
    shutil.copy(src / "truth.json", dst / "truth.json")
    scene = tomllib.loads((src / "scene.toml").read_text())
    if edit:
        edit(scene)
    (dst / "scene.toml").write_text(tomli_w.dumps(scene))
    return dst


def _fit(folder: Path, **options):
    from fitting import FitOptions, fit_folder
    return fit_folder(folder, options=FitOptions(plots=False, **options))


def _right(g, t) -> bool:
    """k within two stated errors of the truth (or an upper bound at or above it), rho within two."""
    if g.identifiable:
        k_ok = abs(g.range_k - t["range_k"]) <= 2 * g.range_stderr
    else:
        k_ok = g.range_k >= t["range_k"]
    return k_ok and abs(g.rho - t["rho"]) <= 2 * g.rho_stderr


def _right_or_flagged(g, t, *causes: str) -> None:
    """Right, or not reliable with a warning that names one of ``causes`` (any, when none given)."""
    assert g.error is None, g.error
    if _right(g, t):
        return
    text = " ".join(g.warnings)
    assert not g.reliable and g.warnings, (g.label, g.range_k, g.rho, t["range_k"], t["rho"])
    assert not causes or any(c in text for c in causes), (g.label, g.warnings)


T09 = ["IMG_0001.jpg", "IMG_0002.jpg", "IMG_0003.jpg"]


@pytest.mark.parametrize("scale", [1.05, 1.1, 1.3])
def test_an_object_described_too_large_is_flagged_and_named(table2_640, tmp_path, scale):
    """scale = 1.05-1.3 in [object]: every photo misfits; none is left out, and the warning names the
    object's size (once: the one photo left read reliable with k +100 % and rho 4-6 sigma off)."""
    def bigger(scene):
        scene["object"]["scale"] = scale
    (g,) = _fit(_copy(table2_640, tmp_path / "f", T09, bigger)).groups
    assert len(g.photos) == 3 and not g.reliable
    assert "the fitted shadow does not match the photos" in " ".join(g.warnings)
    _right_or_flagged(g, _truth(table2_640)["09"], "object's size")
    assert not g.identifiable and g.range_k >= _truth(table2_640)["09"]["range_k"]


def test_a_clock_twelve_minutes_off_names_the_clock(table2_640, tmp_path):
    import piexif
    folder = _copy(table2_640, tmp_path / "f", T09)
    for name in T09:
        exif = piexif.load(str(folder / name))
        when = dt.datetime.strptime(exif["Exif"][piexif.ExifIFD.DateTimeOriginal].decode(), "%Y:%m:%d %H:%M:%S")
        exif["Exif"][piexif.ExifIFD.DateTimeOriginal] = (when + dt.timedelta(minutes=12)).strftime(
            "%Y:%m:%d %H:%M:%S").encode()
        piexif.insert(piexif.dump(exif), str(folder / name))
    (g,) = _fit(folder).groups
    text = " ".join(g.warnings)
    assert not g.reliable and "likely the clock" in text and "minutes earlier" in text, g.warnings
    assert "raise --range-k-max" not in text


def test_gray_frames_are_no_shadow_and_the_other_group_is_right_or_flagged(table2_640, tmp_path):
    """The 13:21 photos replaced by uniform gray frames (EXIF kept) once read rho 0.995 +- 0.007,
    reliable; the untouched 16:21 group read rho 3.6 sigma off, reliable. A failed group is neither
    reliable nor identifiable, in results.json too."""
    import piexif
    from PIL import Image

    from fitting import write_results_json
    gray = ["IMG_0004.jpg", "IMG_0005.jpg", "IMG_0006.jpg"]
    folder = _copy(table2_640, tmp_path / "f", gray + ["IMG_0007.jpg", "IMG_0008.jpg", "IMG_0009.jpg"])
    for name in gray:
        exif = piexif.dump(piexif.load(str(folder / name)))
        Image.fromarray(np.full((480, 640, 3), 128, np.uint8)).save(folder / name, exif=exif, quality=92)
    results = _fit(folder)
    noon, evening = results.groups
    assert noon.error.startswith("no shadow in view") and noon.rho is None
    assert not noon.reliable and not noon.identifiable
    _right_or_flagged(evening, _truth(table2_640)["16"])
    (data, _) = json.loads(write_results_json(results, tmp_path).read_text())["groups"]
    assert data["error"].startswith("no shadow in view") and data["reliable"] is False and data["identifiable"] is False


def test_the_demo_at_400x300_is_right_or_flagged(table2_400):
    """Once: rho 2.2 and 3.3 sigma off, reliable, and a clean photo left out as "camera registration
    or time off?"."""
    truth = _truth(table2_400)
    results = _fit(table2_400)
    assert len(results.groups) == 3
    for g in results.groups:
        _right_or_flagged(g, truth[g.label[:2]])
    assert not any("camera registration or time off" in s["reason"] for s in results.skipped)


def test_a_fitted_sun_at_400x300_is_right_or_flagged(table2_400, tmp_path):
    """No site: the sun is searched for from the shadows and fitted. Once: elevation 55.0 for 51.1 and
    k 3.9 sigma off, reliable (the re-plans around the sun stopped before it settled)."""
    def no_site(scene):
        del scene["site"]
    (g,) = _fit(_copy(table2_400, tmp_path / "f", T09, no_site)).groups
    assert g.sun_source == "fitted"
    _right_or_flagged(g, _truth(table2_400)["09"], "sun")


def test_a_forced_level_of_detail_on_the_dragon_is_flagged(tmp_path):
    """--lod 1000 on the 26,584-face dragon once read k twice the truth (5 sigma), reliable."""
    folder = _synth(tmp_path, "dragon", 0, (400, 300))
    (g,) = _fit(folder, lod=1000).groups
    assert g.lod_faces is not None and g.lod_faces < g.mesh_faces
    _right_or_flagged(g, _truth(folder)["10"], "level of detail")


def test_a_free_sun_that_wanders_below_the_horizon_is_a_clear_error(monkeypatch):
    """A fitted sun whose refit goes below the horizon (a misdescribed scene with no site) ends as the
    group's error saying so, not as the exception's text."""
    import types

    import fitting.folder.checked as checked
    import fitting.solve.group as solve
    from fitting import FitOptions, PhotoGroup
    from softshadow import SunBelowHorizonError

    def fit_group(model, pose, views, label, time, options, *more, **kw):
        raise SunBelowHorizonError("sun elevation -1.65 deg is at or below the horizon (minimum 0.5 deg)")
    import fitting.photos.sun_search as sun_search
    monkeypatch.setattr(solve, "fit_group", fit_group)
    monkeypatch.setattr(sun_search, "search_sun", lambda *a: sun_search.SunGuess(333.0, 1.0, 0.0))
    views = [types.SimpleNamespace(name="a.jpg", sun_source="fitted", sun_azimuth_deg=None,
                                   sun_elevation_deg=None, time=None)]
    result, left_out = checked.fit_checked(None, None, views, PhotoGroup("10:30", "10:30", ["a.jpg"]),
                                           FitOptions(plots=False), sun_path=None)
    assert result.error.startswith("no sun fits the shadows: the sun fitted from them went below the horizon")
    assert not result.reliable and not result.identifiable and left_out == []
