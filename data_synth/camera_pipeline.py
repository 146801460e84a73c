"""From scene radiance to camera pixels: viewpoints, exposure, vignetting, blur and sensor noise.

Cameras: a handheld-like perspective camera (softshadow.camera.look_at_camera,
placed by compass bearing, distance and eye height, with a little hand
tremor in aim and roll) or a top-down orthographic ground map
(softshadow.camera.GroundGrid, north up).

Sensor model (linear, values in [0, 1] of full scale):
  exposure  s = exposure_white / (reference albedo * E_lit)  (lit white paper -> exposure_white)
  optics    vignetting V(r) = 1 - vignetting * (r / r_corner)^2, then a Gaussian blur (sigma px)
  sensor    electrons ~ Poisson(full_well * x) + Normal(0, read_noise), / full_well, clip to [0, 1]
The light is spectrally flat (as after white balance), so rho is the same in every channel.
"""

from __future__ import annotations

import dataclasses
import math

import cv2
import numpy as np

from softshadow import GroundGrid, PinholeCamera, look_at_camera

__all__ = ["SensorSettings", "handheld_camera", "fit_handheld_camera", "topdown_grid", "expose",
           "apply_optics", "apply_sensor_noise", "camera_pipeline"]


@dataclasses.dataclass(frozen=True)
class SensorSettings:
    """exposure_white: linear value of lit white paper (albedo ``reference_albedo``);
    vignetting: relative fall-off at the image corner; blur_sigma_px: Gaussian optical blur;
    full_well_e: electrons at full scale (shot noise); read_noise_e: Gaussian read noise."""

    exposure_white: float = 0.72
    reference_albedo: float = 0.85
    vignetting: float = 0.25
    blur_sigma_px: float = 0.7
    full_well_e: float = 12000.0
    read_noise_e: float = 4.0

    def __post_init__(self):
        if not (0 < self.exposure_white <= 1 and 0 <= self.vignetting < 1 and self.blur_sigma_px >= 0
                and self.full_well_e > 0 and self.read_noise_e >= 0):
            raise ValueError(f"invalid sensor settings: {self}")


def handheld_camera(target, bearing_deg: float, distance_m: float, eye_height_m: float, width: int,
                    height: int, fov_x_deg: float = 62.0, roll_deg: float = 0.0,
                    aim_jitter_m=(0.0, 0.0)) -> PinholeCamera:
    """A camera ``distance_m`` (horizontal) from ``target`` at compass bearing ``bearing_deg``
    (from the target towards the camera), ``eye_height_m`` above the ground, looking at
    the target (shifted by aim_jitter_m in x, y), rolled by ``roll_deg`` about its axis."""
    target = np.asarray(target, dtype=np.float64)
    b = math.radians(bearing_deg)
    position = target + np.array([math.sin(b) * distance_m, math.cos(b) * distance_m, 0.0])
    position[2] = eye_height_m
    aim = target + np.array([aim_jitter_m[0], aim_jitter_m[1], 0.0])
    return _look(position, aim, width, height, fov_x_deg, roll_deg)


def fit_handheld_camera(key_points: np.ndarray, bearing_deg: float, eye_height_m: float, width: int,
                        height: int, fov_x_deg: float = 62.0, margin: float = 0.08, roll_deg: float = 0.0,
                        aim_jitter_m=(0.0, 0.0), min_distance_m: float = 1.5) -> PinholeCamera:
    """A handheld camera at a bearing that frames all key points (N, 3) tightly.

    The camera stands at the bearing from the key points' centre, at the nearest
    distance (steps of 8 %) where, after re-aiming so that the key points' image
    bounding box is centred, every key point lies inside the frame with a margin.
    aim_jitter_m then shifts the aim (hand tremor; it may push points out).
    """
    pts = np.asarray(key_points, dtype=np.float64).reshape(-1, 3)
    centre = np.array([*(pts[:, :2].min(0) + pts[:, :2].max(0)) / 2, 0.0])
    b = math.radians(bearing_deg)
    away = np.array([math.sin(b), math.cos(b), 0.0])
    mu, mv = margin * width, margin * height

    def framed(distance):
        position = centre + away * distance
        position[2] = eye_height_m
        aim = centre.copy()
        cam = handheld_camera(aim, bearing_deg, distance, eye_height_m, width, height, fov_x_deg, roll_deg)
        for _ in range(4):  # re-aim at the ground point under the key points' image centre
            uv, front = cam.project(pts)
            if not front.all():
                break
            c = (uv.min(0) + uv.max(0)) / 2
            g, ok = cam.ground_points(np.array([c[0]]), np.array([c[1]]))
            if not ok[0]:
                break
            aim = g[0]
            cam = _look(position, aim, width, height, fov_x_deg, roll_deg)
        uv, front = cam.project(pts)
        inside = (front & (uv[:, 0] > mu) & (uv[:, 0] < width - 1 - mu) & (uv[:, 1] > mv)
                  & (uv[:, 1] < height - 1 - mv))
        return cam, position, aim, bool(inside.all())

    distance = min_distance_m
    for _ in range(60):
        cam, position, aim, ok = framed(distance)
        if ok:
            break
        distance *= 1.08
    if aim_jitter_m[0] or aim_jitter_m[1]:
        cam = _look(position, aim + np.array([aim_jitter_m[0], aim_jitter_m[1], 0.0]), width, height,
                    fov_x_deg, roll_deg)
    return cam


def _look(position, aim, width, height, fov_x_deg, roll_deg) -> PinholeCamera:
    cam = look_at_camera(position, aim, width, height, fov_x_deg)
    if roll_deg:
        c, s = math.cos(math.radians(roll_deg)), math.sin(math.radians(roll_deg))
        R = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1.0]]) @ cam.R
        cam = PinholeCamera(cam.K, R, -R @ np.asarray(position, dtype=np.float64), width, height)
    return cam


def topdown_grid(centre_xy, width: int, height: int, pixel_m: float) -> GroundGrid:
    """A north-up ground map of width x height pixels centred on centre_xy."""
    ox = centre_xy[0] - (width - 1) / 2 * pixel_m
    oy = centre_xy[1] + (height - 1) / 2 * pixel_m
    return GroundGrid(float(pixel_m), (float(ox), float(oy)), int(width), int(height))


def expose(radiance: np.ndarray, lit_irradiance: float, settings: SensorSettings, gain: float = 1.0) -> np.ndarray:
    """Scale radiance (albedo * E) so that lit paper reads settings.exposure_white * gain."""
    scale = settings.exposure_white * gain / (settings.reference_albedo * lit_irradiance)
    return (radiance * scale).astype(np.float32)


def apply_optics(image: np.ndarray, settings: SensorSettings) -> np.ndarray:
    """Radial vignetting then Gaussian blur, on a linear image (H, W, C)."""
    h, w = image.shape[:2]
    yy, xx = np.mgrid[0:h, 0:w].astype(np.float32)
    r2 = ((xx - (w - 1) / 2) ** 2 + (yy - (h - 1) / 2) ** 2) / (((w - 1) / 2) ** 2 + ((h - 1) / 2) ** 2)
    out = image * (1.0 - settings.vignetting * r2)[..., None]
    if settings.blur_sigma_px > 0:
        out = cv2.GaussianBlur(out, (0, 0), settings.blur_sigma_px, borderType=cv2.BORDER_REFLECT)
    return out.astype(np.float32)


def apply_sensor_noise(image: np.ndarray, settings: SensorSettings, rng: np.random.Generator) -> np.ndarray:
    """Poisson-Gaussian noise and clipping to [0, 1] (linear, full scale = full_well_e electrons)."""
    electrons = rng.poisson(np.clip(image, 0.0, None).astype(np.float64) * settings.full_well_e)
    electrons = electrons + rng.normal(0.0, settings.read_noise_e, image.shape)
    return np.clip(electrons / settings.full_well_e, 0.0, 1.0).astype(np.float32)


def camera_pipeline(radiance: np.ndarray, lit_irradiance: float, settings: SensorSettings,
                    rng: np.random.Generator, gain: float = 1.0) -> np.ndarray:
    """Exposure, vignetting, blur and noise: linear sensor image (H, W, 3) in [0, 1]."""
    return apply_sensor_noise(apply_optics(expose(radiance, lit_irradiance, settings, gain), settings),
                              settings, rng)
