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
or whose residual is several times the others', is left out (the caller refits without
it); a group where no photo shows a shadow has "no shadow in view"; when two photos
disagree and neither can be blamed, the group is marked unreliable.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from .results import GroupResult

__all__ = ["PhotoAgreement", "Verdict", "photo_agreement", "judge", "NO_SHADOW_DEPTH", "DEPTH_RATIO",
           "RESIDUAL_RATIO"]

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


@dataclasses.dataclass
class PhotoAgreement:
    """One photo against its group's fit: rms (relative residual), shadow_depth (observed lit minus
    umbra, relative; NaN when either side has too few samples), predicted_depth (the same for the fit)."""

    photo: str
    rms: float
    shadow_depth: float
    predicted_depth: float


@dataclasses.dataclass
class Verdict:
    """What to do with a group: ``leave_out`` (photo, one-line reason) to refit without (at most one
    photo per verdict: the others may only have been bent by it); ``no_shadow`` (a reason) when no
    photo shows a shadow; ``warnings`` that make the group unreliable when nothing can be left out."""

    leave_out: list[tuple[str, str]] = dataclasses.field(default_factory=list)
    no_shadow: str | None = None
    warnings: list[str] = dataclasses.field(default_factory=list)


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
        out.append(PhotoAgreement(p.photo, rms, depth, predicted))
    return out


def _others(values: list[float], i: int) -> float:
    rest = [v for j, v in enumerate(values) if j != i and np.isfinite(v)]
    return float(np.median(rest)) if rest else float("nan")


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
