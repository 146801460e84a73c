"""Level of detail chosen by visual masking: the coarsest level the current lights hide.

The Dowling paper (*Shadow Mapping and Visual Masking in Level of Detail Systems*) found by eye
that patterned projected light hides a simplified mesh's facets, and proposed that a level of
detail system choose the mesh for the lights of the moment. Here:

- ``MaskingScene``: a view and its lights, the paper's set-up (a slide projector above and
  beside the camera, an ambient term) with the sun optionally added;
- ``masked_ssim``: the judge, SSIM (scikit-image, Gaussian window sigma 1.5) between a level's
  image and the full mesh's under the same lights, over the pixels where either shows the
  object or its shadows; a level counts as hidden at ``HIDDEN_SSIM``;
- ``MaskingTable``: for one view, that SSIM measured for every level on a grid of lights (the
  slide's amplitude and frequency, the sun's range k), interpolated for the lights of any frame
  (no level is rendered then), with a margin: the table's own interpolation error, measured by
  leaving out each inner grid value in turn. ``MaskingTable.choose`` gives the coarsest level
  whose predicted SSIM less the margin reaches the threshold;
- ``measure_masking_table``: renders the grid once per view (``render_frame``).

The paper's own scheme "uses lookup tables to allow the use of a more sophisticated image
comparison method"; this is such a table, with SSIM as the comparison.
"""

from __future__ import annotations

import dataclasses
import functools
from collections.abc import Sequence

import numpy as np

from .camera import PinholeCamera, look_at_camera
from .params import Sun
from .projector import Projector
from .scene_render import SceneLights
from .slides import sine_slide

__all__ = ["HIDDEN_SSIM", "MaskingScene", "MaskingTable", "masked_ssim", "comparison_region", "render_level_image",
           "measure_masking_table"]

#: SSIM from which a level counts as hidden (a conventional mark for "hard to tell apart").
HIDDEN_SSIM = 0.95


@dataclasses.dataclass(frozen=True)
class MaskingScene:
    """A view and its lights (world metres, the object standing on z = 0 near the origin).

    The defaults are the Dowling grid's: a three-quarter view, a slide projector above and
    beside the camera (its slides ``sine_slide(frequency, amplitude)``), an ambient term; the
    sun (``sun_azimuth_deg``/``sun_elevation_deg``, irradiance ``sun_irradiance`` on a surface
    facing it) when ``sun_irradiance`` > 0. Albedo 0.85 everywhere.
    """

    camera_position: tuple = (0.9, -3.3, 1.5)
    camera_target: tuple = (0.0, 0.0, 0.5)
    camera_fov_deg: float = 36.0
    width: int = 640
    height: int = 480
    projector_position: tuple = (-0.6, -2.8, 2.4)
    projector_target: tuple = (0.0, 0.0, 0.5)
    projector_fov_deg: float = 38.0
    slide_px: int = 512
    shadow_px: int = 1024
    ambient: float = 0.12
    sun_azimuth_deg: float = 250.0
    sun_elevation_deg: float = 35.0
    sun_irradiance: float = 0.6
    albedo: float = 0.85

    def camera(self, supersample: int = 1) -> PinholeCamera:
        """The camera, with supersample x supersample pixels for each of the image's."""
        return look_at_camera(self.camera_position, self.camera_target, self.width * supersample,
                              self.height * supersample, self.camera_fov_deg)

    def projector(self, amplitude: float, frequency: float) -> Projector:
        """The projector with the sine slide of this amplitude and frequency (0: the spotlight)."""
        return Projector(self.projector_position, self.projector_target, _slide(float(frequency), float(amplitude),
                                                                               int(self.slide_px)),
                         fov_deg=self.projector_fov_deg, shadow_px=self.shadow_px)

    def sun_at(self, azimuth_offset_deg: float = 0.0) -> Sun | None:
        """The sun (None without one), its azimuth turned by an offset."""
        if self.sun_irradiance <= 0:
            return None
        return Sun(self.sun_azimuth_deg + azimuth_offset_deg, self.sun_elevation_deg)

    def sun_description(self) -> str:
        if self.sun_irradiance <= 0:
            return "none"
        return (f"azimuth {self.sun_azimuth_deg:g} deg, elevation {self.sun_elevation_deg:g} deg, "
                f"irradiance {self.sun_irradiance:g}")

    def lights(self, range_k: float = 0.01) -> SceneLights:
        return SceneLights(self.ambient, max(self.sun_irradiance, 0.0), range_k)


@functools.lru_cache(maxsize=64)
def _slide(frequency: float, amplitude: float, size: int) -> np.ndarray:
    slide = sine_slide(frequency, amplitude, size)
    slide.setflags(write=False)
    return slide


def comparison_region(*masks: np.ndarray, dilate_px: int = 3) -> np.ndarray:
    """The pixels (H, W) bool where any of the masks is set, dilated by ``dilate_px``: what a
    comparison of two images of the object looks at (its outline counts)."""
    import cv2
    union = np.zeros(masks[0].shape, np.uint8)
    for m in masks:
        union |= m.astype(np.uint8)
    return cv2.dilate(union, np.ones((2 * dilate_px + 1,) * 2, np.uint8)) > 0


def masked_ssim(full: np.ndarray, level: np.ndarray, region: np.ndarray) -> float:
    """SSIM of two images (H, W) (grey, linear) averaged over ``region`` (H, W) bool.

    scikit-image's ``structural_similarity``, Gaussian window of sigma 1.5 (Wang et al. 2004),
    the data range of both images together.
    """
    from skimage.metrics import structural_similarity
    lo, hi = min(full.min(), level.min()), max(full.max(), level.max())
    _, smap = structural_similarity(full, level, data_range=float(hi - lo) or 1.0, gaussian_weights=True,
                                    sigma=1.5, use_sample_covariance=False, full=True)
    return float(smap[region].mean())


@dataclasses.dataclass(frozen=True)
class MaskingTable:
    """SSIM of each level of detail against the full mesh, measured for one view on a grid of
    lights, and the choice it predicts for any lights.

    faces (L,): the levels' face counts, finest first (faces[0] the full mesh, SSIM 1);
    amplitudes (A,), frequencies (F,): the slides' grid (``sine_slide``; frequency 0 is the
    plain spotlight); ranges_k (K,): the sun's k (empty without a sun); ssim (A, F, K', L) with
    K' = max(K, 1); margin: how far the interpolation overestimates a left-out measurement
    (``with_margin``); threshold: the SSIM from which a level counts as hidden.
    """

    faces: tuple[int, ...]
    amplitudes: tuple[float, ...]
    frequencies: tuple[float, ...]
    ranges_k: tuple[float, ...]
    ssim: np.ndarray
    margin: float = 0.0
    threshold: float = HIDDEN_SSIM

    def __post_init__(self):
        ssim = np.asarray(self.ssim, np.float64)
        shape = (len(self.amplitudes), len(self.frequencies), max(len(self.ranges_k), 1), len(self.faces))
        if ssim.shape != shape:
            raise ValueError(f"masking table needs ssim of shape {shape}, got {ssim.shape}")
        for name, axis in (("amplitudes", self.amplitudes), ("frequencies", self.frequencies),
                           ("ranges_k", self.ranges_k)):
            if len(axis) > 1 and np.any(np.diff(axis) <= 0):
                raise ValueError(f"masking table {name} must increase, got {axis}")
        if list(self.faces) != sorted(self.faces, reverse=True):
            raise ValueError(f"masking table levels must be finest first, got {self.faces}")
        object.__setattr__(self, "ssim", ssim)

    def predict(self, amplitude: float, frequency: float, range_k: float | None = None) -> np.ndarray:
        """The SSIM (L,) of each level under these lights: multilinear in the amplitude, in
        log(1 + frequency) and in k, between the grid's values (held at its ends beyond them)."""
        coords = [(np.asarray(self.amplitudes, float), float(amplitude)),
                  (np.log1p(np.asarray(self.frequencies, float)), float(np.log1p(max(frequency, 0.0))))]
        if self.ranges_k:
            coords.append((np.asarray(self.ranges_k, float), float(range_k if range_k is not None else 0.0)))
        return _multilinear(self.ssim if self.ranges_k else self.ssim[:, :, 0], coords)

    def choose(self, amplitude: float, frequency: float, range_k: float | None = None) -> int:
        """The index of the coarsest level whose predicted SSIM, less the margin, reaches the
        threshold (0, the full mesh, when none does)."""
        ok = np.flatnonzero(self.predict(amplitude, frequency, range_k) - self.margin >= self.threshold)
        return int(max(ok.max(initial=0), 0))

    def with_margin(self) -> "MaskingTable":
        """This table with its margin measured: each inner value of each axis left out in turn,
        predicted from the rest, and the largest amount by which a prediction exceeds the
        measurement, over the predictions within 0.1 of the threshold (where the choice turns)."""
        over = [0.0]
        axes = [("amplitudes", 0), ("frequencies", 1), ("ranges_k", 2)]
        for name, axis in axes:
            values = getattr(self, name)
            for i in range(1, len(values) - 1):
                keep = [j for j in range(len(values)) if j != i]
                reduced = dataclasses.replace(self, **{name: tuple(values[j] for j in keep)},
                                              ssim=np.take(self.ssim, keep, axis=axis), margin=0.0)
                for a in range(len(self.amplitudes)):
                    for f in range(len(self.frequencies)):
                        for k in range(max(len(self.ranges_k), 1)):
                            if (a, f, k)[axis] != i:
                                continue
                            got = reduced.predict(self.amplitudes[a], self.frequencies[f],
                                                  self.ranges_k[k] if self.ranges_k else None)
                            measured = self.ssim[a, f, k]
                            near = np.abs(np.minimum(got, measured) - self.threshold) < 0.1
                            if near.any():
                                over.append(float(np.max((got - measured)[near])))
        return dataclasses.replace(self, margin=max(over))

    def to_json(self) -> dict:
        return {"faces": list(self.faces), "amplitudes": list(self.amplitudes),
                "frequencies": list(self.frequencies), "ranges_k": list(self.ranges_k),
                "ssim": np.round(self.ssim, 5).tolist(), "margin": round(self.margin, 5),
                "threshold": self.threshold}

    @classmethod
    def from_json(cls, data: dict) -> "MaskingTable":
        return cls(tuple(int(f) for f in data["faces"]), tuple(data["amplitudes"]), tuple(data["frequencies"]),
                   tuple(data["ranges_k"]), np.asarray(data["ssim"]), float(data.get("margin", 0.0)),
                   float(data.get("threshold", HIDDEN_SSIM)))


def _multilinear(values: np.ndarray, coords: list) -> np.ndarray:
    """values (n1, ..., nd, L) at a point: linear along each axis between its two grid values
    around the point's coordinate (clamped to the axis' range); coords [(axis values, x), ...]."""
    out = values
    for grid, x in coords:
        if len(grid) == 1:
            out = out[0]
            continue
        x = min(max(x, grid[0]), grid[-1])
        i = int(np.clip(np.searchsorted(grid, x, side="right") - 1, 0, len(grid) - 2))
        t = (x - grid[i]) / (grid[i + 1] - grid[i])
        out = (1.0 - t) * out[i] + t * out[i + 1]
    return out


def render_level_image(scene: MaskingScene, model, amplitude: float, frequency: float,
                       range_k: float | None, supersample: int = 2, renderer=None):
    """A level's image (H, W) grey and the pixels (H, W) bool where it shows the object or the
    sun's shadow (cast on anything else), rendered with ``render_frame`` at supersample x
    supersample samples per pixel and averaged."""
    from .params import Pose
    from .scene_frame import render_frame
    s = int(supersample)
    camera = scene.camera(s)
    sun = scene.sun_at() if range_k is not None else None
    lights = scene.lights(range_k if range_k is not None else 0.01)
    args = (camera, model, Pose(), lights, sun, [scene.projector(amplitude, frequency)])
    kwargs = dict(object_albedo=scene.albedo, ground_albedo=scene.albedo)
    frame = renderer.render(*args, **kwargs) if renderer is not None else render_frame(*args, **kwargs)
    h, w = scene.height, scene.width
    grey = frame.image.mean(axis=-1).reshape(h, s, w, s).mean(axis=(1, 3))
    shows = (frame.visible.surface == 0)
    if frame.plan is not None:
        # The sun's cast shadow and penumbra on anything but the object (whose own pixels count anyway).
        shadow = np.zeros(camera.height * camera.width, bool)
        shaded = np.asarray(frame.plan.hard) > 0
        shaded[frame.plan.band] = True
        shadow[frame.visible.pixel] = shaded
        shows = shows | shadow.reshape(camera.height, camera.width)
    return grey, shows.reshape(h, s, w, s).any(axis=(1, 3))


def measure_masking_table(scene: MaskingScene, levels: Sequence, amplitudes: Sequence[float],
                          frequencies: Sequence[float], ranges_k: Sequence[float] = (), supersample: int = 2,
                          progress=None) -> MaskingTable:
    """The ``MaskingTable`` of ``levels`` (``SoftShadowModel`` of each level of detail with its
    ``faces``: [(faces, model), ...], finest first, the full mesh first) seen in ``scene``,
    its margin measured (``with_margin``). ranges_k: the sun's k (empty: no sun)."""
    from .scene_frame import FrameRenderer
    faces = tuple(int(f) for f, _ in levels)
    ks = tuple(float(k) for k in ranges_k) or (None,)
    ssim = np.ones((len(amplitudes), len(frequencies), len(ks), len(levels)))
    renderer = FrameRenderer(threads=1)
    try:
        for ik, k in enumerate(ks):
            for ia, a in enumerate(amplitudes):
                for jf, f in enumerate(frequencies):
                    if f == 0 and ia > 0:  # the plain spotlight: the amplitude changes nothing
                        ssim[ia, jf, ik] = ssim[0, jf, ik]
                        continue
                    if progress:
                        progress(f"masking table: amplitude {a:g}, frequency {f:g}" + (f", k {k:g}" if k else ""))
                    full, full_mask = render_level_image(scene, levels[0][1], a, f, k, supersample, renderer)
                    full = full.copy()
                    for il, (_, model) in enumerate(levels[1:], start=1):
                        img, mask = render_level_image(scene, model, a, f, k, supersample, renderer)
                        ssim[ia, jf, ik, il] = masked_ssim(full, img, comparison_region(full_mask, mask))
    finally:
        renderer.close()
    return MaskingTable(faces, tuple(float(a) for a in amplitudes), tuple(float(f) for f in frequencies),
                        tuple(float(k) for k in ranges_k), ssim).with_margin()
