"""Result records of a fit: what ``fit_folder`` returns and ``softshadow fit`` writes.

Plain dataclasses whose ``to_json`` gives exactly the documented
``results.json`` fields; plot data rides along in ``ProfilePlotData`` and
``OverlayPlotData`` (not written to JSON).
"""

from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np

from softshadow import brightness_to_paper, range_to_paper

__all__ = ["ProfilePlotData", "OverlayPlotData", "GroupResult", "FitResults"]


@dataclasses.dataclass
class ProfilePlotData:
    """Observed against fitted values across the shadow edge, for one photo of a group.

    distance_px (n,) signed distance of each sample from the fitted hard-shadow boundary
    in image pixels (positive = lit side); observed (n,), fitted (n,) in linear units
    normalised by the photo's lit level; profile_id (n,) which edge profile a sample
    belongs to (for drawing individual profiles).
    """

    photo: str
    distance_px: np.ndarray
    observed: np.ndarray
    fitted: np.ndarray
    profile_id: np.ndarray


@dataclasses.dataclass
class OverlayPlotData:
    """The fitted shadow over a photo: image (h, w) linear gray, possibly a downsampled copy of the
    photo; alpha (h, w) fitted alpha on the same pixels (NaN where not modelled); samples_uv (n, 2)
    the pixels used by the fit, in the photo's own pixels; photo_shape (H, W) the photo's size
    (None: the image is the photo at full size)."""

    photo: str
    image: np.ndarray
    alpha: np.ndarray
    samples_uv: np.ndarray
    photo_shape: tuple[int, int] | None = None


@dataclasses.dataclass
class GroupResult:
    """One time of day (or one photo, without a scene). Fields as in results.json (docs/formats.md).

    range_k and rho are physical values; ``range`` and ``brightness`` are the paper's units
    (100 k and 255 rho^(1/2.2)); *_stderr are one-sigma in physical units. When
    ``identifiable`` is False, range_k is an upper bound. ``error`` holds a one-line reason
    when the group could not be fitted (then the numeric fields are None). ``warnings`` are
    one-line notes; ``reliable`` is False when the measurement failed a consistency check
    (the values are still given, but do not trust their error bars).
    """

    label: str
    time: str | None
    photos: list[str]
    range_k: float | None = None
    range_stderr: float | None = None
    rho: float | None = None
    rho_stderr: float | None = None
    # The stated *_stderr split into its statistical and systematic parts (fitting.solve.uncertainty);
    # stated = hypot(stat, sys).
    range_stderr_stat: float | None = None
    rho_stderr_stat: float | None = None
    range_stderr_sys: float | None = None
    rho_stderr_sys: float | None = None
    sun_azimuth_deg: float | None = None
    sun_elevation_deg: float | None = None
    sun_source: str | None = None  # "given", "time+site", "fitted"
    rmse: float | None = None
    n_profiles: int = 0
    n_samples: int = 0
    converged: bool = False
    identifiable: bool = True
    seconds: float = 0.0
    solve_seconds: float | None = None  # the least-squares part of ``seconds`` (no sampling, plots)
    profile: str | None = None  # penumbra profile used: "linear" or "disk"
    blur_px: float | None = None
    penumbra_px: float | None = None
    penumbra_px_iqr: float | None = None
    penumbra_m: float | None = None
    reprojection_error_px: float | None = None
    lod_faces: int | None = None  # faces of the level of detail fitted (``fitting.solve.lod``)
    mesh_faces: int | None = None  # faces of the object's mesh as given
    warnings: list[str] = dataclasses.field(default_factory=list)
    reliable: bool = True
    error: str | None = None
    plot_profiles: list[ProfilePlotData] = dataclasses.field(default_factory=list, repr=False)
    plot_overlays: list[OverlayPlotData] = dataclasses.field(default_factory=list, repr=False)

    @property
    def fitted(self) -> bool:
        return self.error is None and self.rho is not None

    @property
    def range(self) -> float | None:
        return None if self.range_k is None else float(range_to_paper(self.range_k))

    @property
    def brightness(self) -> float | None:
        return None if self.rho is None else float(brightness_to_paper(max(self.rho, 0.0)))

    def to_json(self) -> dict[str, Any]:
        out: dict[str, Any] = {
            "label": self.label, "time": self.time, "photos": list(self.photos),
            "range": _num(self.range), "range_k": _num(self.range_k),
            "range_stderr": _num(self.range_stderr),
            "brightness": _num(self.brightness), "rho": _num(self.rho),
            "rho_stderr": _num(self.rho_stderr),
            "sun_azimuth_deg": _num(self.sun_azimuth_deg),
            "sun_elevation_deg": _num(self.sun_elevation_deg),
            "rmse": _num(self.rmse), "n_profiles": int(self.n_profiles),
            "converged": bool(self.converged), "identifiable": bool(self.identifiable),
            "seconds": round(float(self.seconds), 3),
            "warnings": list(self.warnings), "reliable": bool(self.reliable),
        }
        optional = {"range_stderr_stat": _num(self.range_stderr_stat), "rho_stderr_stat": _num(self.rho_stderr_stat),
                    "range_stderr_sys": _num(self.range_stderr_sys), "rho_stderr_sys": _num(self.rho_stderr_sys),
                    "sun_source": self.sun_source, "profile": self.profile,
                    "blur_px": _num(self.blur_px), "n_samples": self.n_samples or None,
                    "penumbra_px": _num(self.penumbra_px),
                    "penumbra_px_iqr": _num(self.penumbra_px_iqr),
                    "penumbra_m": _num(self.penumbra_m),
                    "reprojection_error_px": _num(self.reprojection_error_px),
                    "lod_faces": self.lod_faces, "mesh_faces": self.mesh_faces,
                    "solve_seconds": None if self.solve_seconds is None else round(float(self.solve_seconds), 3),
                    "error": self.error}
        out.update({k: v for k, v in optional.items() if v is not None})
        return out

    @classmethod
    def from_json(cls, data: dict) -> "GroupResult":
        names = {f.name for f in dataclasses.fields(cls)}
        return cls(**{k: v for k, v in data.items() if k in names})


def _num(x):
    if x is None:
        return None
    x = float(x)
    return x if np.isfinite(x) else None


@dataclasses.dataclass
class FitResults:
    """All groups of a folder, the skipped photos with reasons, and software versions."""

    groups: list[GroupResult]
    skipped: list[dict]
    software: dict

    @property
    def n_fitted(self) -> int:
        """Groups with values from a converged fit (a solve that stopped early is not a fit)."""
        return sum(g.fitted and g.converged for g in self.groups)

    def to_json(self) -> dict[str, Any]:
        return {"groups": [g.to_json() for g in self.groups], "skipped": list(self.skipped),
                "software": dict(self.software)}
