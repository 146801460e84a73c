"""The coarse sun search (fitting.photos.sun_search): it reads the shadow's outline, not the ground's
own light and dark areas, and tells a thin shadow's length (the elevation) as well as its way."""

import numpy as np
import pytest

from fitting import PhotoView
from fitting.photos.sun_search import search_sun
from softshadow import GroundGrid, Pose, ShadowParams, SoftShadowModel, Sun


def _along(sun: Sun) -> np.ndarray:
    """The ground direction (2,) away from the sun (x east, y north)."""
    az = np.radians(sun.azimuth_deg)
    return np.array([-np.sin(az), -np.cos(az)])


def _sheet_on_asphalt(grid: GroundGrid, sun: Sun, length_m: float) -> np.ndarray:
    """Albedo (H, W): dark asphalt, and a white sheet laid along the shadow (the study's set-up
    that fooled a search by darkness: the asphalt is darker than the shadowed sheet)."""
    xy = grid.to_world(*np.meshgrid(np.arange(grid.width), np.arange(grid.height)))[..., :2]
    xy = xy.reshape(grid.height, grid.width, 2)
    along = _along(sun)
    across = np.array([-along[1], along[0]])
    s, t = xy @ along, xy @ across
    sheet = (s > -0.1) & (s < length_m + 0.4) & (np.abs(t) < 0.25)
    return np.where(sheet, 0.85, 0.25)


@pytest.mark.parametrize("sun", [Sun(236.0, 49.0), Sun(120.0, 18.0)])
def test_the_search_finds_a_thin_shadow_on_a_sheet(sun):
    model = SoftShadowModel.from_mesh("pillar", profile="disk")  # 3 m tall, 0.2 m wide
    pose = Pose()
    length = 3.0 / np.tan(np.radians(sun.elevation_deg))  # the whole shadow in view
    grid = GroundGrid.around(tuple(0.5 * length * _along(sun)), 1.3 * length + 1.0, 160)
    shade = np.asarray(model.ground_map(ShadowParams(0.005, 0.15), sun, pose, grid))
    rng = np.random.default_rng(0)
    gray = (_sheet_on_asphalt(grid, sun, length) * shade * rng.normal(1.0, 0.03, shade.shape)).astype(np.float32)
    view = PhotoView("top.png", gray, np.zeros(gray.shape, bool), grid=grid)
    guess = search_sun(model, pose, [view])
    turn = (guess.azimuth_deg - sun.azimuth_deg + 180.0) % 360.0 - 180.0
    assert abs(turn) <= 2.0 and abs(guess.elevation_deg - sun.elevation_deg) <= 3.0, guess


def test_no_receiver_in_view_is_a_clear_error():
    model = SoftShadowModel.from_mesh("pillar")
    grid = GroundGrid.around((0.0, 0.0), 6.0, 64)
    gray = np.zeros((64, 64), np.float32)  # nothing lit: no pixel can vote
    with pytest.raises(ValueError, match="no photo shows enough of the receiver"):
        search_sun(model, Pose(), [PhotoView("dark.png", gray, np.zeros(gray.shape, bool), grid=grid)])
