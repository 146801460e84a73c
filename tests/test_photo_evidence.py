"""A photo's evidence against its group's fit (``fitting.solve.evidence.photo_evidence``): the depth
gap, sample by sample, on a receiver whose lit level varies."""

import numpy as np
import pytest

from fitting.samples.receiver_light import shadow_factor
from fitting.solve.evidence import photo_evidence
from fitting.solve.model import Prediction


def _stepped_photo(umbra_offset: float, seed: int = 0):
    """Samples of a lit ground beyond the penumbra (u = 5) and of an umbra (u = -5) on a receiver
    with two kinds of faces: 55 % facing as the ground (sun_cos 1), 45 % turned to the sun (3), so
    the fitted level is two-valued on each side. observed = the fit + 5 % noise, its umbra moved by
    umbra_offset (relative to the lit level)."""
    rng = np.random.default_rng(seed)
    n, rho = 2000, 0.3
    lit = np.arange(n) < n // 2
    sun_cos = np.where(np.arange(n) % 20 < 11, 1.0, 3.0)
    sky_hidden = np.zeros(n)
    alpha = np.where(lit, 0.0, 1.0)
    values = shadow_factor(alpha, rho, sun_cos, 1.0)
    observed = values + 0.05 * rng.standard_normal(n) + np.where(lit, 0.0, umbra_offset)
    prediction = Prediction(values, alpha, np.where(lit, 5.0, -5.0), np.ones(n))
    return photo_evidence("a.jpg", observed, prediction, rho, sun_cos, sky_hidden)


def test_the_depth_gap_does_not_move_with_a_two_valued_level():
    e = _stepped_photo(0.0)
    # The difference of the two regions' medians parts from the fit's (the case this guards) ...
    assert e.shadow_depth - e.predicted_depth > 0.045
    # ... while the residuals' medians agree: the photo's shadow is as deep as the fitted one.
    assert abs(e.depth_gap) < 0.01


@pytest.mark.parametrize("offset", [-0.06, 0.06])
def test_the_depth_gap_reads_a_deeper_or_shallower_umbra(offset):
    """An umbra darker than the fitted one by 0.06 of the lit level reads a gap of +0.06."""
    e = _stepped_photo(offset)
    assert e.depth_gap == pytest.approx(-offset, abs=0.01)


def test_the_depth_gap_needs_samples_on_both_sides():
    n = 30
    prediction = Prediction(np.ones(n), np.zeros(n), np.full(n, 5.0), np.ones(n))
    e = photo_evidence("a.jpg", np.ones(n), prediction, 0.3, np.ones(n), np.zeros(n))
    assert np.isnan(e.depth_gap) and np.isnan(e.shadow_depth)
