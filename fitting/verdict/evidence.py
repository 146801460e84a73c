"""What the rule book judges: typed evidence that the fit hands it (frozen records, NumPy-free).

The fit measures; the rule book (``fitting.verdict.rules``) decides. Everything a verdict may
depend on is here, as numbers and names, so that the rules are pure functions of these records and
can be tested without a fit:

- ``PhotoEvidence``: one photo against its group's fit: its residuals per region (the lit ground
  beyond the penumbra, the umbra, the penumbra between), the noise measured on the lit ground and
  in the umbra (robust: the normal-scaled median absolute deviation of the residuals there), the
  misfit of the whole photo in units of that noise, the shadow's depth observed and fitted, and the
  photo's own estimate of k and rho (the group's fit moved to this photo's samples alone).
- ``FitEvidence``: one group's fit: its values and their errors (statistical and stated), the
  penumbra's width, the sample counts under the fitted shadow, the photos' evidence and the
  one-line facts the fit found (a photo without the shadow in view).
- ``GroupContext``: what lies around the fit: the photos given and those left out, the level of
  detail of the mesh, a diagnostic refit with the sun free (``SunCheck``).
- ``EdgeEvidence``: a photo measured without geometry (``fitting.edges.measure``): the modes of its
  profiles' rho, how the kept profiles lie on the image, the outlines' rho, the dark sides.

Residuals are relative to the fitted lit level (1 is the lit ground's brightness). NaN marks a
number that could not be measured (too few samples).
"""

from __future__ import annotations

import dataclasses
import math

__all__ = ["PhotoEvidence", "FitEvidence", "SunFree", "SunCheck", "LevelOfDetail", "GroupContext", "EdgeEvidence", "NAN"]

NAN = math.nan


@dataclasses.dataclass(frozen=True)
class PhotoEvidence:
    """One photo against its group's fit.

    n_samples: the photo's samples; n_lit, n_umbra, n_penumbra: those on the lit ground (alpha
    below 0.01, a margin beyond the penumbra), in the umbra (alpha at least 0.99, the same margin)
    and inside the penumbra (|u| < 1).
    rms, rms_lit, rms_umbra, rms_penumbra: the residual's root mean square over all samples and
    per region. noise_lit, noise_umbra: the robust spread (normal-scaled MAD) of the residuals on
    the lit ground and in the umbra: the photo's noise and texture, which the model does not
    describe. misfit: the root mean square of the residuals in units of the noise expected at each sample
    (the lit ground's noise on the lit side, the umbra's in the umbra, between them by alpha),
    over the 90 % of samples with the smallest such ratio: about 1 when the model describes
    what the photo shows, whatever its texture.
    shadow_depth, predicted_depth: the observed and the fitted lit level minus the umbra level
    (relative) where the shadow's geometry puts them (beyond the penumbra on either side, whatever
    the photo's fitted blur), NaN with fewer than 10 samples on either side. depth_gap: how much
    deeper the photo's shadow is than the fitted one, sample by sample: the median residual on that
    lit side minus the median residual in that umbra (relative; NaN as above). Unlike the difference
    of the two depths, it does not move when the fitted level varies within a region (a receiver's
    faces turned differently to the sun), where medians of observed and fitted values part.
    k, k_stderr, rho, rho_stderr: the photo's own estimate (the group's fit moved to this
    photo's samples alone, to first order) and its statistical error.
    """

    photo: str
    n_samples: int
    n_lit: int
    n_umbra: int
    n_penumbra: int
    rms: float
    rms_lit: float = NAN
    rms_umbra: float = NAN
    rms_penumbra: float = NAN
    noise_lit: float = NAN
    noise_umbra: float = NAN
    misfit: float = NAN
    shadow_depth: float = NAN
    predicted_depth: float = NAN
    depth_gap: float = NAN
    k: float = NAN
    k_stderr: float = NAN
    rho: float = NAN
    rho_stderr: float = NAN


@dataclasses.dataclass(frozen=True)
class SunFree:
    """The group's solve repeated on the same samples with the sun's azimuth and elevation free:
    how far the sun moved (degrees) from its elevation ``elevation_deg``, and k and rho there. A sun
    known from its time and site moves little when the scene is described right, and k and rho do
    not follow it."""

    d_azimuth_deg: float
    d_elevation_deg: float
    k: float
    rho: float
    elevation_deg: float = 45.0


@dataclasses.dataclass(frozen=True)
class FitEvidence:
    """One group's fit.

    k, rho: the fitted values; k_stderr_stat, rho_stderr_stat: their statistical errors (the
    larger of the classic and the cluster-robust one); k_stderr_sys, rho_stderr_sys: their
    systematic errors (the calibrated floor, ``fitting.solve.uncertainty``); the stated error is the
    two in quadrature.
    penumbra_px: the fitted penumbra's median width in image pixels over the samples inside it
    (None: no sample is); blur_px: the photos' fitted camera blur (root mean square; None: not
    fitted). n_in_penumbra, n_in_umbra: the group's samples inside the fitted penumbra (|u| < 1)
    and in the fitted umbra (alpha, blur included, at least 0.99). no_ramp_k: when no sample lies
    inside the fitted penumbra, the largest k the samples allow (None: not known).
    penumbra_px_per_k: the penumbra's width in image pixels per unit k at the shadow's outline (the
    width any k would have; None: not known).
    n_profiles: stretches of shadow edge sampled; converged: the solver's outcome.
    range_k_max: the largest k the samples' band was planned for. sun_fitted: the sun was fitted
    with k and rho (not known from a time and site, or given). photos: each photo's evidence.
    photos_without_shadow: (photo, reason) for photos that were not sampled (no shadow in view).
    sun_free: the solve with the sun free (None: the sun was fitted anyway).
    receiver: the surface the shadow falls on: "plane" (the ground), "depth" (range images) or "mesh".
    remaining_step_se: how far one more Gauss-Newton step from the solution would still move k or
    rho, in units of their statistical errors (the larger of the two; NaN: not known). A solver
    that stopped on its step limit with this small has settled k and rho (a k that creeps towards
    0 under a penumbra narrower than a pixel, for example).
    rule: the rule that drew the fit's penumbra ("edge", "paper" or "wedge"); rule_asked: the one
    ``FitOptions.rule`` asked for ("auto" included); rule_unavailable: why the wedge rule asked for
    (or by "auto") could not be planned for these photos (None: it could, or was not asked for).
    """

    k: float
    rho: float
    k_stderr_stat: float
    rho_stderr_stat: float
    k_stderr_sys: float
    rho_stderr_sys: float
    penumbra_px: float | None
    blur_px: float | None
    n_in_penumbra: int
    n_in_umbra: int
    n_profiles: int
    converged: bool
    range_k_max: float
    photos: tuple[PhotoEvidence, ...] = ()
    no_ramp_k: float | None = None
    sun_fitted: bool = False
    photos_without_shadow: tuple[tuple[str, str], ...] = ()
    sun_free: SunFree | None = None
    receiver: str = "plane"
    remaining_step_se: float = NAN
    rule: str = "edge"
    rule_asked: str = "edge"
    rule_unavailable: str | None = None
    penumbra_px_per_k: float | None = None


@dataclasses.dataclass(frozen=True)
class SunCheck:
    """A diagnostic refit of a group with the sun free (its azimuth and elevation fitted with k
    and rho): how far the sun moved (degrees), the misfit before and after (the photos' median
    ``PhotoEvidence.misfit``), k after; the sun's elevation (degrees) and its daily path at the
    group's time, (d azimuth, d elevation) in degrees per minute (None: not known, no site);
    sun_given: the sun was given in scene.toml (not computed from a time and the site)."""

    d_azimuth_deg: float
    d_elevation_deg: float
    misfit_before: float
    misfit_after: float
    k_after: float
    elevation_deg: float = 45.0
    path_deg_per_min: tuple[float, float] | None = None
    sun_given: bool = False


@dataclasses.dataclass(frozen=True)
class LevelOfDetail:
    """The mesh level fitted: ``faces`` of the mesh's ``mesh_faces``; ``forced``: a face count
    the user asked for (not chosen); shift_k_se, shift_rho_se: how far the level moves k and rho
    against the full mesh, in their standard errors, to first order (``fitting.solve.lod``; NaN:
    not checked). note: why no level could be chosen (the full mesh was used), or None."""

    faces: int | None = None
    mesh_faces: int | None = None
    forced: bool = False
    shift_k_se: float = NAN
    shift_rho_se: float = NAN
    note: str | None = None


@dataclasses.dataclass(frozen=True)
class GroupContext:
    """What lies around one group's fit: the number of photos given to the group, the photos
    left out of it with their reasons, the level of detail, a diagnostic refit with the sun free
    (None: not run), and when the sun was fitted, how far it moved (degrees, azimuth plus elevation)
    in the last of the refits that re-plan the samples around it (None: not fitted); when the fit was
    repeated with a wider band of samples (``rules.wants_wider_band``), the band's k it was first
    planned for and the k it read then (None: not repeated)."""

    photos_given: int = 0
    left_out: tuple[tuple[str, str], ...] = ()
    level_of_detail: LevelOfDetail = LevelOfDetail()
    sun_check: SunCheck | None = None
    sun_last_move_deg: float | None = None
    band_widened_from: tuple[float, float] | None = None


@dataclasses.dataclass(frozen=True)
class EdgeEvidence:
    """One photo measured from its shadow edges alone (no geometry).

    modes: the separate modes of the shadow-like profiles' log rho as (log peak, profiles), most
    profiles first; measured_log: the mode the reported rho comes from (the highest density).
    n_kept: the profiles the value rests on; n_structures: the separate structures (single-linkage
    clusters of their positions) they lie on; outlines: (median log rho, kept profiles) of each
    of those structures. dark_side_regions: for each dark region holding at least one kept
    profile's dark side, how many it holds (the dark sides that lie in no dark region are not
    counted).
    """

    modes: tuple[tuple[float, int], ...]
    measured_log: float
    n_kept: int
    n_structures: int
    outlines: tuple[tuple[float, int], ...] = ()
    dark_side_regions: tuple[int, ...] = ()
