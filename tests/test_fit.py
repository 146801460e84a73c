"""The fitter end to end: same-model data with known truth, bad input, the CLI contract,
and the independent Mitsuba renders (vendored in tests/data/mitsuba)."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from datapaths import MITSUBA


TRUE_K, TRUE_RHO = 0.012, 0.25
SUN = (150.0, 40.0)


def _render_folder(folder: Path, k=TRUE_K, rho=TRUE_RHO, noise=0.004, seed=0, size=192):
    """A top-down 16-bit linear PNG of the pillar's soft shadow (disk profile), with scene.toml."""
    from data_synth import model_topdown_folder
    return model_topdown_folder(folder, k, rho, noise, seed, size, SUN)


@pytest.fixture(scope="module")
def same_model_folder(tmp_path_factory):
    return _render_folder(tmp_path_factory.mktemp("same_model"))


def test_same_model_fit_recovers_truth_with_honest_errors(same_model_folder):
    from fitting.folder.api import fit_folder
    from fitting.solve.group import FitOptions
    # The data were rendered by the model alone, without the sky the pillar hides. Both profiles
    # are offered: the data were made with the disk profile, and BIC must see it.
    results = fit_folder(same_model_folder, options=FitOptions(sky_occlusion=False, profiles=("linear", "disk")))
    (g,) = results.groups
    assert g.error is None and g.converged
    assert g.profile == "disk"
    assert abs(g.range_k - TRUE_K) / TRUE_K < 0.05
    assert abs(g.rho - TRUE_RHO) < 0.01
    # One-sigma errors: the truth lies within a few of them (not absurdly small or large).
    assert abs(g.range_k - TRUE_K) < 5 * g.range_stderr + 1e-4
    assert 0 < g.rho_stderr < 0.01
    assert g.identifiable


def test_cli_writes_the_conventions_files_and_refuses_to_overwrite(same_model_folder, tmp_path):
    out = tmp_path / "out"
    cmd = [sys.executable, "-m", "softshadow_cli", "fit", str(same_model_folder), "--out", str(out),
           "--no-plots"]
    first = subprocess.run(cmd, capture_output=True, text=True, timeout=600)
    assert first.returncode == 0, first.stderr
    data = json.loads((out / "results.json").read_text())
    group = data["groups"][0]
    for key in ("label", "time", "photos", "range", "range_k", "range_stderr", "brightness", "rho",
                "rho_stderr", "sun_azimuth_deg", "sun_elevation_deg", "rmse", "n_profiles",
                "converged", "identifiable", "seconds"):
        assert key in group
    # The command line runs JAX in float32 (only the fit itself is scoped to float64): its results
    # must still recover the truth as the float64 test above does.
    assert abs(group["range_k"] - TRUE_K) / TRUE_K < 0.05 and abs(group["rho"] - TRUE_RHO) < 0.01
    assert group["range"] == pytest.approx(100 * group["range_k"])
    assert group["brightness"] == pytest.approx(255 * group["rho"] ** (1 / 2.2))
    assert (out / "table2.md").exists() and (out / "table2.csv").exists()
    assert (out / "groups").is_dir()  # finished groups are kept for resuming
    again = subprocess.run(cmd, capture_output=True, text=True, timeout=600)
    assert again.returncode != 0 and "--force" in again.stderr


def test_fit_called_from_float32_keeps_the_callers_precision(same_model_folder):
    """A float32 caller (the command line, a user's session) gets the same fit, and keeps float32."""
    import jax
    import jax.numpy as jnp

    from fitting.folder.api import fit_folder
    from fitting.solve.group import FitOptions
    with jax.enable_x64(False):
        (g,) = fit_folder(same_model_folder, options=FitOptions(sky_occlusion=False, plots=False)).groups
        assert jnp.zeros(1).dtype == jnp.float32, "the fit must not switch its caller to float64"
    assert g.error is None and g.converged and g.identifiable
    assert abs(g.range_k - TRUE_K) / TRUE_K < 0.05 and abs(g.rho - TRUE_RHO) < 0.01


def _shadow_centre(sun, fraction=0.5, height=3.0):
    """A ground point (x, y) at ``fraction`` of the pillar's shadow, from its base to its tip."""
    az, el = np.radians(sun[0]), np.radians(sun[1])
    length = height / np.tan(el)
    return (-fraction * length * np.sin(az), -fraction * length * np.cos(az))


@pytest.fixture(scope="module")
def hard_fit(tmp_path_factory):
    """One folder, one group per hard case (each with its own sun), fitted once."""
    from fitting.folder.api import fit_folder
    from fitting.solve.group import FitOptions
    import shutil

    from data_synth import model_topdown_folder
    from scene import ObjectSpec, SceneSpec, dump_scene, load_scene
    root = tmp_path_factory.mktemp("hard_fit")
    folder = root / "all"
    folder.mkdir()
    low_sun = (150.0, 8.0)  # a 21 m shadow: map its middle 6 m
    cases = {  # name: (k, rho, sun, centre, extent)
        "low-sun": (TRUE_K, TRUE_RHO, low_sun, _shadow_centre(low_sun), 6.0),
        "k-near-zero": (2e-4, TRUE_RHO, SUN, _shadow_centre(SUN), 2.6),
        "rho-dark": (TRUE_K, 0.03, SUN, _shadow_centre(SUN), 2.6),
        "rho-pale": (TRUE_K, 0.97, SUN, _shadow_centre(SUN), 2.6),
    }
    photos = {}
    for hour, (name, (k, rho, sun, centre, extent)) in enumerate(cases.items()):
        one = model_topdown_folder(root / name, k, rho, seed=hour, sun=sun, centre=centre, extent_m=extent,
                                   time=f"2026-04-20T{8 + 2 * hour:02d}:00:00+09:00", group=name)
        shutil.copy(one / "top.png", folder / f"{name}.png")
        photos[f"{name}.png"] = load_scene(one / "scene.toml").photos["top.png"]
    dump_scene(SceneSpec(object=ObjectSpec("pillar"), photos=photos), folder / "scene.toml")
    results = fit_folder(folder, options=FitOptions(sky_occlusion=False, plots=False))
    return cases, {g.label: g for g in results.groups}


@pytest.mark.parametrize("name", ["low-sun", "rho-dark", "rho-pale"])
def test_hard_fits_recover_the_truth(hard_fit, name):
    """A sun 8 deg high (penumbra 2k d over ~11 m), and rho near its bounds (umbra nearly black,
    or a shadow of 3 % contrast): the truth comes back, within a few of the fit's own errors.
    The photo check may refuse the 3 % shadow (it asks for 5 %), but then with that reason."""
    cases, groups = hard_fit
    k, rho = cases[name][:2]
    g = groups[name]
    if name == "rho-pale" and g.error is not None:
        assert g.error.startswith("no shadow in view") and "3 %" in g.error and g.rho is None, g.error
        return
    assert g.error is None and g.converged and g.identifiable and g.reliable, (g.error, g.warnings)
    assert abs(g.range_k - k) / k < 0.05 and abs(g.range_k - k) < 5 * g.range_stderr + 1e-4
    assert abs(g.rho - rho) < 0.005 and abs(g.rho - rho) < 5 * g.rho_stderr + 1e-3
    assert 0.0 < g.rho < 1.0


def test_hard_fit_with_k_near_zero_is_an_upper_bound(hard_fit):
    """k = 2e-4: the penumbra (~0.5 mm) is far below the 13.5 mm pixel. The range is not
    identifiable and comes back as an upper bound (at least the truth), said in the warnings;
    rho is still measured."""
    cases, groups = hard_fit
    k, rho = cases["k-near-zero"][:2]
    g = groups["k-near-zero"]
    assert g.error is None
    assert g.identifiable is False
    assert g.range_k >= k
    assert g.range_k < 0.006  # a bound at the pixel scale (one 13.5 mm pixel: k ~ 0.0024), not a blank cheque
    assert any("upper bound" in w for w in g.warnings)
    assert abs(g.rho - rho) < 0.005


@pytest.fixture(scope="module")
def hard_cases_preset(tmp_path_factory):
    """The hard-cases preset at 320 x 240, rendered by data_synth's model renderer, fitted once."""
    from data_synth import synthesize
    from data_synth.renderers import RenderQuality
    from fitting.folder.api import fit_folder
    from fitting.solve.group import FitOptions
    quality = RenderQuality(sun_samples=16, sky_samples=256, sky_fine_nodes=48, object_sky_samples=16)
    folder = synthesize(tmp_path_factory.mktemp("hard_cases") / "h", "hard-cases", size=(320, 240),
                        renderer="model", progress=False, render_quality=quality)
    truth = json.loads((folder / "truth.json").read_text())
    return truth, fit_folder(folder, options=FitOptions(plots=False))


def test_hard_cases_preset_reports_its_bad_photos(hard_cases_preset):
    truth, results = hard_cases_preset
    reasons = {s["photo"]: s["reason"] for s in results.skipped}
    for expected in truth["expected_skipped"]:
        assert expected["photo"] in reasons
    notime = [name for name, d in truth["photos_detail"].items() if d["time"] is None]
    assert notime and all("no time" in reasons[name] for name in notime)


# Groups of the preset at 320 x 240 that come back with a wrong value neither flagged as an upper
# bound nor unreliable (strict expected failures with the measured symptom as the reason); none since
# 2026-11-25 (low-sun, subpixel: the penumbra and umbra sample counts; zenith: those and the no-ramp
# bound of k; out-of-frame, clutter: the rule book, fitting.verdict.rules).
HARD_PRESET_FAILURES: dict[str, str] = {}


@pytest.mark.parametrize("label", [
    pytest.param(label, marks=pytest.mark.xfail(reason=HARD_PRESET_FAILURES[label], strict=True))
    if label in HARD_PRESET_FAILURES else label
    for label in ("low-sun", "zenith", "subpixel", "out-of-frame", "clutter")])
def test_hard_cases_preset_recovers_the_truth_or_says_it_cannot(hard_cases_preset, label):
    """Each group: k within 15 % of the truth, or not identifiable with range_k an upper bound;
    rho within 0.02, or the group marked unreliable."""
    truth, results = hard_cases_preset
    t = {g["label"]: g for g in truth["groups"]}[label]
    (g,) = [g for g in results.groups if g.label == label]
    assert g.error is None, g.error
    if g.identifiable:
        assert abs(g.range_k - t["range_k"]) / t["range_k"] < 0.15, (g.range_k, t["range_k"])
    else:
        assert g.range_k >= t["range_k"] and any("upper bound" in w for w in g.warnings)
    assert abs(g.rho - t["rho"]) < 0.02 or not g.reliable, (g.rho, t["rho"], g.reliable)


def test_bad_files_are_skipped_with_reasons_and_do_not_stop_the_rest(tmp_path):
    from fitting.folder.api import fit_folder
    folder = _render_folder(tmp_path / "mixed", seed=3)
    (folder / "broken.jpg").write_bytes(b"\xff\xd8\xff\xe0 not really a jpeg")
    (folder / "notes.txt").write_text("hello")
    results = fit_folder(folder)
    reasons = {s["photo"]: s["reason"] for s in results.skipped}
    assert "broken.jpg" in reasons and "notes.txt" in reasons
    assert results.n_fitted == 1


def test_no_shadow_in_view_is_a_group_error_not_a_crash(tmp_path):
    from fitting.folder.api import fit_folder
    folder = _render_folder(tmp_path / "empty")
    # Move the map far from the shadow: nothing to fit there.
    text = (folder / "scene.toml").read_text().replace("origin_m = [", "origin_m = [50.0, 50.0, ")
    import re
    text = re.sub(r"origin_m = \[50.0, 50.0, [^\]]*\]", "origin_m = [50.0, 50.0]", text)
    (folder / "scene.toml").write_text(text)
    results = fit_folder(folder)
    (g,) = results.groups
    assert g.error is not None and "shadow" in g.error
    assert results.n_fitted == 0


def test_a_penumbra_under_a_pixel_is_reported_as_an_upper_bound(tmp_path):
    """k = 0.0005 throws a penumbra of about 0.2 px here: k is not identifiable, range_k is an
    upper bound above the truth, and the group says so."""
    from fitting.folder.api import fit_folder
    from fitting.solve.group import FitOptions
    folder = _render_folder(tmp_path / "sharp", k=0.0005)
    (g,) = fit_folder(folder, options=FitOptions(sky_occlusion=False, plots=False)).groups
    assert g.error is None
    assert not g.identifiable
    assert g.range_k >= 0.0005
    assert g.penumbra_px is None or g.penumbra_px < 0.8
    assert any("upper bound" in w for w in g.warnings)
    assert abs(g.rho - TRUE_RHO) < 0.01  # rho is still measured
    data = g.to_json()
    assert data["identifiable"] is False


@pytest.mark.parametrize("name", ["pillar-yaw30-topdown", "ball-topdown", "pillar-sun1deg-photo"])
def test_independent_mitsuba_renders(name):
    folder = MITSUBA / name
    from fitting.folder.api import fit_folder
    truth = json.loads((folder / "truth.json").read_text())["groups"][0]
    (g,) = fit_folder(folder).groups
    assert g.error is None
    assert abs(g.range_k - truth["range_k"]) / truth["range_k"] < 0.10
    assert abs(g.rho - truth["rho"]) < 0.012  # the sky the object hides darkens the umbra a little
    # The stated one-sigma errors (systematic floor included, fitting.solve.uncertainty) cover the truth
    # of these independent renders within two sigma; the statistical part alone did not for k.
    assert abs(g.range_k - truth["range_k"]) <= 2 * g.range_stderr
    assert abs(g.rho - truth["rho"]) <= 2 * g.rho_stderr
    assert g.range_stderr_stat is not None and g.range_stderr_stat < g.range_stderr


def test_board_registration_and_fitted_sun_from_a_synthetic_folder(tmp_path):
    """No cameras and no site in scene.toml: the ChArUco board gives the cameras and the
    shadow itself gives the sun (the physical renderer's folder, so not the fitter's model)."""
    import re

    from data_synth import synthesize
    from fitting.folder.api import fit_folder
    folder = synthesize(tmp_path / "markers", preset="pillar", seed=1, size=(800, 600),
                        cameras="markers", progress=False)
    text = (folder / "scene.toml").read_text()
    (folder / "scene.toml").write_text(re.sub(r"\[site\][^\[]*", "", text, count=1))
    truth = json.loads((folder / "truth.json").read_text())["groups"][0]
    (g,) = fit_folder(folder).groups
    assert g.error is None, g.error
    assert g.sun_source == "fitted"
    assert g.reprojection_error_px is not None and g.reprojection_error_px < 1.0
    assert abs(g.sun_azimuth_deg - truth["sun_azimuth_deg"]) < 0.5
    assert abs(g.sun_elevation_deg - truth["sun_elevation_deg"]) < 0.5
    # At 800x600 the penumbra spans only 2-4 pixels, so k is loose here; the accuracy
    # targets are checked at full size by the Mitsuba tests and the benchmark.
    assert abs(g.range_k - truth["range_k"]) / truth["range_k"] < 0.3
    assert abs(g.rho - truth["rho"]) < 0.02
