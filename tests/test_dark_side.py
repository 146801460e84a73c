"""The dark side of a cast shadow is one connected region (fitting.edges.cues.dark_side_regions, and the
rule book's fitting.verdict.edge_rules.scattered_dark_sides), on tiny synthetic log images, and end to end
on one synthetic shadow."""

from __future__ import annotations

import numpy as np
from scipy import ndimage

from fitting.edges.cues import dark_side_regions
from fitting.verdict import edge_rules


def scattered_dark_sides(labels):
    """The rule book's warning on dark-region labels (0: in no dark region)."""
    labels = np.asarray(labels, int)
    return edge_rules.scattered_dark_sides(tuple(np.unique(labels[labels > 0], return_counts=True)[1]))

H, W = 64, 80
LIT, UMBRA = np.log(0.5), np.log(0.5 * 0.3)
THRESHOLD = 0.5 * (LIT + UMBRA)


def _textured(rng, dark):
    """Log image: lit ground with 0.15 log units of texture, dark (rho 0.3) where ``dark``."""
    tex = ndimage.gaussian_filter(rng.standard_normal((H, W)), 0.7)
    return np.where(dark, UMBRA, LIT) + 0.15 * tex / tex.std()


def _outline_samples(dark, step_px=2):
    """(N, 2) (u, v) of dark pixels next to the lit side (where a profile's dark side would be sampled)."""
    rim = dark & ~ndimage.binary_erosion(dark, iterations=step_px)
    v, u = np.nonzero(rim)
    return np.stack([u, v], axis=1)[::7].astype(float)


def test_one_connected_shadow_puts_every_dark_side_in_one_region():
    rng = np.random.default_rng(0)
    dark = np.zeros((H, W), bool)
    dark[10:50, 15:30] = True           # a person's shadow: a body ...
    dark[40:50, 15:70] = True           # ... and a long thin arm, one region
    uv = _outline_samples(dark)
    labels = dark_side_regions(_textured(rng, dark), np.ones((H, W), bool), uv, THRESHOLD)
    assert uv.shape[0] >= 10
    assert np.all(labels > 0) and np.unique(labels).size == 1
    assert scattered_dark_sides(labels) is None


def test_dark_blobs_on_unrelated_structures_are_flagged():
    rng = np.random.default_rng(1)
    dark = np.zeros((H, W), bool)
    centres = [(8, 8), (8, 40), (8, 70), (30, 20), (30, 55), (52, 8), (52, 40), (52, 70)]
    for v, u in centres:                # dark stones, gaps and stains, one edge each
        dark[v - 3:v + 4, u - 3:u + 4] = True
    uv = np.array([(u - 2, v) for v, u in centres], float)
    labels = dark_side_regions(_textured(rng, dark), np.ones((H, W), bool), uv, THRESHOLD)
    assert np.unique(labels[labels > 0]).size == len(centres)
    warning = scattered_dark_sides(labels)
    assert warning is not None and "8 separate dark regions" in warning


def test_a_masked_strip_does_not_join_two_blobs_and_a_sample_off_the_dark_pixels_takes_its_neighbours_label():
    log = np.full((H, W), LIT)
    log[20:40, 10:30] = UMBRA
    log[20:40, 50:70] = UMBRA
    valid = np.ones((H, W), bool)
    log[20:40, 30:50] = UMBRA           # a dark bridge between them ...
    valid[:, 38:42] = False             # ... cut by the user's mask
    labels = dark_side_regions(log, valid, np.array([[15.0, 30.0], [65.0, 30.0], [31.0, 19.0], [5.0, 5.0]]),
                               THRESHOLD)
    assert labels[0] > 0 and labels[1] > 0 and labels[0] != labels[1]
    assert labels[2] == labels[0]       # one pixel above the region: its neighbours' label
    assert labels[3] == 0               # on lit ground


def test_a_few_profiles_in_the_main_shadow_and_some_strays_are_not_flagged():
    assert scattered_dark_sides(np.array([1] * 6 + [2, 3, 4, 0, 0])) is None
    assert scattered_dark_sides(np.array([1, 1, 2, 3, 4, 5])) is not None
    assert scattered_dark_sides(np.array([0, 0, 0, 1])) is None      # too few judged


def test_a_measured_shadow_is_not_warned_about_scattered_dark_sides(monkeypatch):
    import fitting.edges.measure as edge_measure

    seen = []
    regions = edge_measure.dark_side_regions

    def spy(*args):
        seen.append(regions(*args))
        return seen[-1]

    monkeypatch.setattr(edge_measure, "dark_side_regions", spy)
    rng = np.random.default_rng(2)
    yy, xx = np.mgrid[0:96, 0:128]
    d = np.maximum(np.abs(xx - 64) - 30, np.abs(yy - 48) - 22)        # a rectangle, signed distance (px)
    shade = 1.0 - np.clip(0.5 - d / 4.0, 0.0, 1.0) * 0.7
    tex = ndimage.gaussian_filter(rng.standard_normal(shade.shape), 0.7)
    photo = 0.4 * np.exp(0.1 * tex / tex.std()) * shade
    m = edge_measure.measure_shadow_edges(photo + rng.normal(0.0, 0.003, photo.shape))
    assert m.edges_found and abs(m.rho - 0.3) < 0.03
    assert not any("dark sides scattered" in w for w in m.warnings)
    # Every kept profile's dark side was sampled inside the shadow (on the dark side of its normal), in one region.
    assert len(seen) == 1 and seen[0].size == m.n_profiles
    assert np.all(seen[0] > 0) and np.unique(seen[0]).size == 1
