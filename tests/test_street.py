"""Preset street: an ordinary street photo rendered by the ray-casting renderer, measured without geometry."""

from __future__ import annotations

import json

import pytest

from data_synth import synthesize
from fitting.folder.api import fit_folder


@pytest.fixture(scope="module")
def street_folder(tmp_path_factory):
    return synthesize(tmp_path_factory.mktemp("street") / "out", "street", seed=0, size=(320, 240))


def test_street_folder_is_one_photo_with_truth_and_no_scene(street_folder):
    names = sorted(p.name for p in street_folder.iterdir())
    assert names == ["street_0.jpg", "truth.json"]
    truth = json.loads((street_folder / "truth.json").read_text())
    (group,) = truth["groups"]
    assert group["photos"] == ["street_0.jpg"] and truth["preset"] == "street"
    # The occluders hide some sky from their own umbra: a little darker than open ground.
    assert group["umbra_pixels"] > 50
    assert 0.0 < group["rho"] - group["rho_umbra"] < 0.03
    with pytest.raises(ValueError, match="physical renderer only"):
        synthesize(street_folder.parent / "model", "street", renderer="model", size=(64, 48))


def test_street_rho_is_within_0_03_or_marked_unreliable(street_folder):
    truth = json.loads((street_folder / "truth.json").read_text())["groups"][0]
    (group,) = fit_folder(street_folder).groups
    assert group.error is None and group.rho is not None
    assert abs(group.rho - truth["rho"]) < 0.03 or not group.reliable, (group.rho, truth["rho"], group.warnings)
    assert group.reliable == (not group.warnings)
    # Without geometry the stated error holds the bootstrap part and the systematic floor.
    assert group.rho_stderr_sys > 0 and group.rho_stderr_stat > 0
    assert group.rho_stderr == pytest.approx((group.rho_stderr_stat ** 2 + group.rho_stderr_sys ** 2) ** 0.5)
