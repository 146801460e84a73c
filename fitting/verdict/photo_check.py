"""Does each photo of a group agree with the group's fit? (NumPy only, after a fit.)

One bad frame in a group (the lens cap on, the shadow out of view, a wrong clock, a
camera registered a few degrees off) bends the shared k and rho without a word: the
fit compromises between the photos. Each photo is therefore measured against the
group's fit, from the fit's own profile data (``GroupResult.plot_profiles``: observed
and fitted values across the shadow edge, both divided by the photo's fitted lit level):

- ``shadow_depth``: the observed lit level minus the observed umbra level, where the fit
  puts the lit side and the umbra (beyond half the fitted penumbra plus a pixel from the
  boundary). About 1 - rho when the photo shows the shadow where the model puts it,
  about 0 when it shows none there.
- ``rms``: the root mean square of (observed - fitted), relative to the lit level.

``judge`` turns these into decisions: a photo that shows no shadow where the others do,
whose umbra is not one level while theirs is (below), or whose residual is several times
the others', is left out (the caller refits without
it); a group where no photo shows a shadow has "no shadow in view"; when two photos
disagree and neither can be blamed, the group is marked unreliable.

It also checks that the model describes what each photo shows (``fit_quality``):

- the umbra is one level: lit only by the sky, its residual (relative to the lit level)
  is at most the lit ground's (texture scales with the irradiance, shot noise with its
  square root). An umbra whose residual is several times the lit ground's holds more
  than one level: part of it is another surface, or pixels of a white sheet taken for
  ground (a sheet cut in two by the shadow and the frame's border), and rho is a
  compromise between them;
- the ground's texture is small beside the shadow's step: where the lit ground's
  residual (its texture, which the model does not describe) is a large part of the
  step from lit to umbra, texture edges pass for the penumbra and shift both levels,
  so neither k nor rho is measured.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from ..report.results import GroupResult

__all__ = ["PhotoAgreement", "Verdict", "photo_agreement", "judge", "fit_quality", "NO_SHADOW_DEPTH",
           "DEPTH_RATIO", "RESIDUAL_RATIO", "UMBRA_RESIDUAL_RATIO", "UMBRA_RESIDUAL_MIN", "TEXTURE_DEPTH_RATIO"]

#: A photo whose umbra is less than this much darker than its lit ground (relative) shows no shadow:
#: even an overcast sky's faint shadow (rho 0.95) is not a soft shadow that k and rho can describe.
NO_SHADOW_DEPTH = 0.05
#: A photo whose shadow depth is below this fraction of the other photos' (median) shows no shadow
#: where the model puts one, while they do.
DEPTH_RATIO = 0.25
#: A photo whose residual is above this multiple of the other photos' (median) does not fit them.
#: On clean synthetic table2 folders the largest ratio seen was 1.7; one photo registered 3 degrees
#: off read 13, a wrong time 2.9 (caught by its depth), a gray frame 3.2.
RESIDUAL_RATIO = 3.0
_MIN_SIDE_SAMPLES = 10  # samples needed on each side of the edge to measure a depth
#: A photo's umbra does not fit one level when its residual RMS is above this multiple of its lit
#: ground's and above UMBRA_RESIDUAL_MIN (relative to the lit level). Measured 2026-11-24: 0.2-1.3
#: times on the Mitsuba renders, the demo (table2, 1600x1200), the pillar and ball presets at
#: 640x480 and same-model folders (at most 0.026 absolute); 8.2 (0.177) on the hard-cases
#: preset's shadow that runs out of the frame, where half of the sheet's shadowed part was taken
#: for ground (rho 0.389 for 0.30).
UMBRA_RESIDUAL_RATIO = 3.0
UMBRA_RESIDUAL_MIN = 0.03
#: The ground's texture rivals the shadow when the lit ground's residual RMS is above this fraction
#: of the fitted shadow depth (1 - rho, relative), the photos' median. Measured 2026-11-24: at
#: most 0.14 on the folders above (the demo's 16:22 photo, rho 0.47), 0.25 on the hard-cases
#: preset's low sun (rho 0.62); 0.37 on its cluttered ground (k +32 %, rho 0.323 for 0.28).
TEXTURE_DEPTH_RATIO = 0.3


@dataclasses.dataclass
class PhotoAgreement:
    """One photo against its group's fit: rms (relative residual), shadow_depth (observed lit minus
    umbra, relative; NaN when either side has too few samples), predicted_depth (the same for the fit);
    n_lit, n_umbra: samples on each side (beyond the penumbra); rms_lit, rms_umbra: the relative
    residual's RMS there (NaN without samples)."""

    photo: str
    rms: float
    shadow_depth: float
    predicted_depth: float
    n_lit: int = 0
    n_umbra: int = 0
    rms_lit: float = float("nan")
    rms_umbra: float = float("nan")


@dataclasses.dataclass
class Verdict:
    """What to do with a group: ``leave_out`` (photo, one-line reason) to refit without (at most one
    photo per verdict: the others may only have been bent by it); ``no_shadow`` (a reason) when no
    photo shows a shadow; ``warnings`` that make the group unreliable when nothing can be left out."""

    leave_out: list[tuple[str, str]] = dataclasses.field(default_factory=list)
    no_shadow: str | None = None
    warnings: list[str] = dataclasses.field(default_factory=list)
    range_unmeasured: str | None = None  # why k is not measured (then an upper bound), or None


def photo_agreement(result: GroupResult) -> list[PhotoAgreement]:
    """Per-photo agreement from a fitted group's profile data (empty when it has none)."""
    half_width = 0.5 * float(result.penumbra_px or 0.0) + 1.0
    out = []
    for p in result.plot_profiles:
        observed, fitted, dist = (np.asarray(a, dtype=np.float64) for a in (p.observed, p.fitted, p.distance_px))
        ok = np.isfinite(observed) & np.isfinite(fitted)
        if not ok.any():
            continue
        rms = float(np.sqrt(np.mean((observed[ok] - fitted[ok]) ** 2)))
        lit = ok & np.isfinite(dist) & (dist > half_width)
        umbra = ok & np.isfinite(dist) & (dist < -half_width)
        if lit.sum() >= _MIN_SIDE_SAMPLES and umbra.sum() >= _MIN_SIDE_SAMPLES:
            depth = float(np.median(observed[lit]) - np.median(observed[umbra]))
            predicted = float(np.median(fitted[lit]) - np.median(fitted[umbra]))
        else:
            depth = predicted = float("nan")
        side_rms = lambda sel: float(np.sqrt(np.mean((observed[sel] - fitted[sel]) ** 2))) if sel.any() else float("nan")
        out.append(PhotoAgreement(p.photo, rms, depth, predicted, int(lit.sum()), int(umbra.sum()),
                                  side_rms(lit), side_rms(umbra)))
    return out


def _others(values: list[float], i: int) -> float:
    rest = [v for j, v in enumerate(values) if j != i and np.isfinite(v)]
    return float(np.median(rest)) if rest else float("nan")


def _umbra_levels(a: PhotoAgreement) -> str | None:
    """Why a photo's umbra is not one level (module docstring), or None."""
    if (a.n_umbra >= _MIN_SIDE_SAMPLES and a.rms_umbra > UMBRA_RESIDUAL_MIN
            and a.rms_umbra > UMBRA_RESIDUAL_RATIO * a.rms_lit):
        return (f"the umbra is not one level (its residual {a.rms_umbra:.3f} is "
                f"{a.rms_umbra / max(a.rms_lit, 1e-12):.1f} times the lit ground's, {a.rms_lit:.3f}): another "
                "surface, or part of a white sheet taken for ground, lies in the shadow")
    return None


def _two_level_umbrae(agreement: list[PhotoAgreement]) -> list[tuple[PhotoAgreement, str]]:
    """The photos whose umbra is not one level, each with its reason (``_umbra_levels``)."""
    return [(a, reason) for a in agreement if (reason := _umbra_levels(a))]


def fit_quality(agreement: list[PhotoAgreement]) -> tuple[list[str], str | None]:
    """Whether the model describes what the photos show (module docstring): one-line warnings that
    make the group unreliable, and the reason k is not measured (the texture rule) or None."""
    warnings = [f"{a.photo}: {reason}; rho is a compromise" for a, reason in _two_level_umbrae(agreement)]
    ratios = [a.rms_lit / a.predicted_depth for a in agreement
              if a.n_lit >= _MIN_SIDE_SAMPLES and np.isfinite(a.rms_lit) and a.predicted_depth > 0]
    if ratios and np.median(ratios) > TEXTURE_DEPTH_RATIO:
        warnings.append(f"the ground's texture rivals the shadow (lit residual {100 * np.median(ratios):.0f} % of the "
                        f"shadow's depth, above {100 * TEXTURE_DEPTH_RATIO:.0f} %): texture edges pass for the "
                        "penumbra and shift the levels; rho is not measured reliably")
        return warnings, "the ground's texture hides the penumbra's width"
    return warnings, None


def judge(agreement: list[PhotoAgreement]) -> Verdict:
    """Decide on a group from its photos' agreement (see the module docstring for the rules)."""
    verdict = Verdict()
    if not agreement:
        return verdict
    depths = [a.shadow_depth for a in agreement]
    measured = [d for d in depths if np.isfinite(d)]
    if measured and all(d < NO_SHADOW_DEPTH for d in measured):
        verdict.no_shadow = (f"no shadow in view: no photo is darker where the model puts the shadow "
                             f"(umbra at most {100 * max(measured):.0f} % below the lit ground; at least "
                             f"{100 * NO_SHADOW_DEPTH:.0f} % is needed)")
        return verdict
    verdict.warnings, verdict.range_unmeasured = fit_quality(agreement)
    if len(agreement) < 2:
        return verdict
    # A photo without the shadow the others show: its depth is decisive even for two photos.
    candidates = []
    for i, a in enumerate(agreement):
        others = _others(depths, i)
        if np.isfinite(a.shadow_depth) and others >= NO_SHADOW_DEPTH and a.shadow_depth < DEPTH_RATIO * others:
            candidates.append((a.shadow_depth / others, a.photo,
                               f"no shadow edge where the model puts one (the umbra is {100 * max(a.shadow_depth, 0):.0f} % "
                               f"below the lit ground, {100 * others:.0f} % in the other photos): shadow out of view, "
                               "lens cap on, wrong time or wrong camera?"))
    if candidates:
        _, name, reason = min(candidates)
        verdict.leave_out.append((name, reason))
        return verdict
    # A photo whose umbra holds two levels while the others' hold one: the fit without it measures rho.
    two_levels = _two_level_umbrae(agreement)
    if two_levels and len(two_levels) < len(agreement):
        a, reason = max(two_levels, key=lambda pair: pair[0].rms_umbra / max(pair[0].rms_lit, 1e-12))
        verdict.leave_out.append((a.photo, reason))
        return verdict
    rms = [a.rms for a in agreement]
    worst = int(np.argmax(rms))
    others = _others(rms, worst)
    ratio = rms[worst] / max(others, 1e-12)
    if ratio > RESIDUAL_RATIO:
        if len(agreement) >= 3:
            verdict.leave_out.append((agreement[worst].photo,
                                      f"does not fit the other photos of its group: residual {rms[worst]:.3f}, "
                                      f"{ratio:.1f} times theirs ({others:.3f}): camera registration or time off?"))
        else:
            names = " and ".join(a.photo for a in agreement)
            verdict.warnings.append(f"{names} disagree (residuals {rms[0]:.3f} and {rms[1]:.3f}); with two photos "
                                    "the one that is off cannot be told: check their cameras and times")
    return verdict
