"""Result records of a fit: what ``fit_folder`` returns and ``softshadow fit`` writes.

A group's result (``GroupResult``) is built from typed, frozen parts: the values and errors as
reported and the verdict on them (both from the rule book, ``fitting.verdict``), the sun the fit
used, diagnostics of the fit, and plot data. ``to_json`` gives exactly the documented
``results.json`` fields (docs/formats.md, with the extra fields it allows); plot data rides along
(``ProfilePlotData``, ``OverlayPlotData``) and is not written.
"""

from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np

from softshadow import brightness_to_paper, range_to_paper

from ..verdict.evidence import FitEvidence
from ..verdict.outcome import Estimate, Verdict
from ..verdict.rules import failed

__all__ = ["ProfilePlotData", "OverlayPlotData", "PlotData", "SunUsed", "FitDiagnostics", "Estimate", "Verdict",
           "GroupResult", "FitResults"]


@dataclasses.dataclass(frozen=True)
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


@dataclasses.dataclass(frozen=True)
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


@dataclasses.dataclass(frozen=True)
class PlotData:
    """What a group's plots are drawn from: per-photo profiles and overlays (either may be empty)."""

    profiles: tuple[ProfilePlotData, ...] = ()
    overlays: tuple[OverlayPlotData, ...] = ()


@dataclasses.dataclass(frozen=True)
class SunUsed:
    """The sun the fit used (degrees; after its fitted correction) and where it came from:
    "given", "time+site" or "fitted"."""

    azimuth_deg: float | None = None
    elevation_deg: float | None = None
    source: str | None = None


@dataclasses.dataclass(frozen=True)
class FitDiagnostics:
    """How the fit went: rmse (relative residual), n_profiles and n_samples, converged, the
    penumbra profile ("linear" or "disk"), the rule that drew it ("edge", "paper" or "wedge",
    ``fitting.solve.rule_choice``) and, when the fit chose it, rule_criterion (the RMS difference
    of the two rules' shading at the samples over the photos' noise), blur_px (the photos' camera blur, root mean square),
    the penumbra's median width and interquartile range in pixels (and metres, top-down without
    geometry), the worst camera registration (px), the level of detail fitted (faces of the
    mesh's), and the seconds spent (``solve_seconds``: the least-squares part)."""

    rmse: float | None = None
    n_profiles: int = 0
    n_samples: int = 0
    converged: bool = False
    profile: str | None = None
    rule: str | None = None
    rule_criterion: float | None = None
    blur_px: float | None = None
    penumbra_px: float | None = None
    penumbra_px_iqr: float | None = None
    penumbra_m: float | None = None
    reprojection_error_px: float | None = None
    lod_faces: int | None = None
    mesh_faces: int | None = None
    seconds: float = 0.0
    solve_seconds: float | None = None


def _part(part: str, name: str) -> property:
    """A read-only attribute of a result that is the field ``name`` of its part ``part``."""
    return property(lambda self: getattr(getattr(self, part), name), doc=f"``{part}.{name}``")


@dataclasses.dataclass(frozen=True)
class GroupResult:
    """One time of day (or one photo, without a scene), built from its parts; fields as in
    results.json (docs/formats.md).

    range_k and rho are physical values; ``range`` and ``brightness`` are the paper's units
    (100 k and 255 rho^(1/2.2)); *_stderr are one-sigma in physical units. When
    ``identifiable`` is False, range_k is an upper bound. ``error`` holds a one-line reason
    when the group could not be fitted (then there are no values, and the verdict is neither
    reliable nor identifiable). ``warnings`` are one-line notes; ``reliable`` is False when the
    measurement failed a consistency check (the values are still given, but do not trust their
    error bars). ``evidence``: what the rule book judged (not written).
    """

    label: str
    time: str | None
    photos: tuple[str, ...]
    verdict: Verdict
    estimate: Estimate = Estimate()
    sun: SunUsed = SunUsed()
    diagnostics: FitDiagnostics = FitDiagnostics()
    plots: PlotData = dataclasses.field(default=PlotData(), repr=False)
    error: str | None = None
    evidence: FitEvidence | None = dataclasses.field(default=None, repr=False, compare=False)

    def __post_init__(self):
        object.__setattr__(self, "photos", tuple(self.photos))
        if self.error is not None and (self.verdict.reliable or self.verdict.identifiable):
            raise ValueError("a group with an error is neither reliable nor identifiable")

    @classmethod
    def failed(cls, label: str, time: str | None, photos, error: str, warnings=(),
               diagnostics: FitDiagnostics = FitDiagnostics()) -> "GroupResult":
        """A group that could not be fitted: its one-line ``error`` and no values."""
        return cls(label, time, tuple(photos), failed(warnings), diagnostics=diagnostics, error=error)

    def with_time(self, seconds: float) -> "GroupResult":
        """The same result with ``seconds`` added to the time it took."""
        return dataclasses.replace(self, diagnostics=dataclasses.replace(
            self.diagnostics, seconds=self.diagnostics.seconds + seconds))

    # The flat fields of results.json, read from the parts.
    range_k = _part("estimate", "range_k")
    rho = _part("estimate", "rho")
    range_stderr = _part("estimate", "range_stderr")
    rho_stderr = _part("estimate", "rho_stderr")
    range_stderr_stat = _part("estimate", "range_stderr_stat")
    rho_stderr_stat = _part("estimate", "rho_stderr_stat")
    range_stderr_sys = _part("estimate", "range_stderr_sys")
    rho_stderr_sys = _part("estimate", "rho_stderr_sys")
    reliable = _part("verdict", "reliable")
    identifiable = _part("verdict", "identifiable")
    warnings = property(lambda self: list(self.verdict.warnings), doc="The verdict's warnings (a list).")
    sun_azimuth_deg = _part("sun", "azimuth_deg")
    sun_elevation_deg = _part("sun", "elevation_deg")
    sun_source = _part("sun", "source")
    rmse = _part("diagnostics", "rmse")
    n_profiles = _part("diagnostics", "n_profiles")
    n_samples = _part("diagnostics", "n_samples")
    converged = _part("diagnostics", "converged")
    profile = _part("diagnostics", "profile")
    rule = _part("diagnostics", "rule")
    rule_criterion = _part("diagnostics", "rule_criterion")
    blur_px = _part("diagnostics", "blur_px")
    penumbra_px = _part("diagnostics", "penumbra_px")
    penumbra_px_iqr = _part("diagnostics", "penumbra_px_iqr")
    penumbra_m = _part("diagnostics", "penumbra_m")
    reprojection_error_px = _part("diagnostics", "reprojection_error_px")
    lod_faces = _part("diagnostics", "lod_faces")
    mesh_faces = _part("diagnostics", "mesh_faces")
    seconds = _part("diagnostics", "seconds")
    solve_seconds = _part("diagnostics", "solve_seconds")
    plot_profiles = property(lambda self: list(self.plots.profiles), doc="The profile plot data (a list).")
    plot_overlays = property(lambda self: list(self.plots.overlays), doc="The overlay plot data (a list).")

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
        d = self.diagnostics
        out: dict[str, Any] = {
            "label": self.label, "time": self.time, "photos": list(self.photos),
            "range": _num(self.range), "range_k": _num(self.range_k),
            "range_stderr": _num(self.range_stderr),
            "brightness": _num(self.brightness), "rho": _num(self.rho),
            "rho_stderr": _num(self.rho_stderr),
            "sun_azimuth_deg": _num(self.sun_azimuth_deg),
            "sun_elevation_deg": _num(self.sun_elevation_deg),
            "rmse": _num(d.rmse), "n_profiles": int(d.n_profiles),
            "converged": bool(d.converged), "identifiable": bool(self.identifiable),
            "seconds": round(float(d.seconds), 3),
            "warnings": list(self.warnings), "reliable": bool(self.reliable),
        }
        optional = {"range_stderr_stat": _num(self.range_stderr_stat), "rho_stderr_stat": _num(self.rho_stderr_stat),
                    "range_stderr_sys": _num(self.range_stderr_sys), "rho_stderr_sys": _num(self.rho_stderr_sys),
                    "sun_source": self.sun_source, "profile": d.profile,
                    "rule": d.rule, "rule_criterion": _num(d.rule_criterion),
                    "blur_px": _num(d.blur_px), "n_samples": d.n_samples or None,
                    "penumbra_px": _num(d.penumbra_px),
                    "penumbra_px_iqr": _num(d.penumbra_px_iqr),
                    "penumbra_m": _num(d.penumbra_m),
                    "reprojection_error_px": _num(d.reprojection_error_px),
                    "lod_faces": d.lod_faces, "mesh_faces": d.mesh_faces,
                    "solve_seconds": None if d.solve_seconds is None else round(float(d.solve_seconds), 3),
                    "error": self.error}
        out.update({k: v for k, v in optional.items() if v is not None})
        return out

    @classmethod
    def from_json(cls, data: dict) -> "GroupResult":
        """A result from its results.json fields (a kept group, ``fitting.folder.resume``): the verdict
        as it was written, except that a group with an error is never reliable or identifiable."""
        pick = lambda kind: {f.name: data[f.name] for f in dataclasses.fields(kind) if data.get(f.name) is not None}
        error = data.get("error")
        warnings = tuple(data.get("warnings") or ())
        verdict = (failed(warnings) if error is not None else
                   Verdict(reliable=bool(data.get("reliable", True)), identifiable=bool(data.get("identifiable", True)),
                           warnings=warnings))
        sun = SunUsed(data.get("sun_azimuth_deg"), data.get("sun_elevation_deg"), data.get("sun_source"))
        return cls(data["label"], data.get("time"), tuple(data.get("photos") or ()), verdict,
                   Estimate(**pick(Estimate)), sun, FitDiagnostics(**pick(FitDiagnostics)), error=error)


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
