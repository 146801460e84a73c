"""Choosing the fit's pixels: the paper (albedo) mask."""

from __future__ import annotations

import numpy as np

from fitting.samples.photo_samples import paper_mask


def _scene(shadow: bool = True):
    rng = np.random.default_rng(0)
    img = 0.25 + 0.01 * rng.standard_normal((300, 400))          # ground
    img[20:150, 30:370] = 0.9                                     # a sheet of paper
    if shadow:
        img[75:90, 30:370] = 0.2                                  # a shadow across it
    img[205:290, 280:365] = 0.9                                   # a board's white margin
    img[220:275, 295:350] = 0.05                                  # the board itself
    return img.astype(np.float32)


def test_paper_mask_closes_a_shadow_across_the_sheet_but_not_the_ground_between_pieces():
    mask = paper_mask(_scene(), np.zeros((300, 400), bool))
    assert mask is not None
    assert mask[82, 200], "the shadow across the sheet belongs to the sheet"
    assert mask[50, 200] and mask[120, 200]
    assert mask[210, 320], "the board's margin is a bright sheet of its own"
    assert not mask[175, 320], "the ground between the sheet and the board is not paper"
    assert not mask[10, 200] and not mask[290, 50]


def test_paper_mask_none_without_a_bright_sheet():
    rng = np.random.default_rng(1)
    flat = (0.3 + 0.01 * rng.standard_normal((200, 200))).astype(np.float32)
    assert paper_mask(flat, np.zeros((200, 200), bool)) is None


def test_hidden_sky_fraction_of_a_disk_overhead_matches_its_solid_angle():
    """A disk of radius R at height d hides sin^2(atan(R/d)) = R^2 / (R^2 + d^2) of the
    cosine-weighted sky from the point below its centre, and nothing from far away."""
    import trimesh

    from softshadow.internal import hidden_sky_fraction
    R, d = 1.0, 1.5
    disk = trimesh.creation.cylinder(radius=R, height=0.01, sections=128)
    disk.apply_translation([0.0, 0.0, d])
    h = hidden_sky_fraction(disk, np.array([[0.0, 0.0, 0.0], [500.0, 0.0, 0.0]]), n_directions=4096)
    assert abs(h[0] - R**2 / (R**2 + d**2)) < 0.005
    assert h[1] == 0.0
