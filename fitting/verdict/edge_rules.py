"""The rule book of a photo measured without geometry (``fitting.edges.measure``): from its cues
(``EdgeEvidence``, computed by ``fitting.edges.cues``) it alone decides the warnings and ``reliable``.

- **The edges disagree**: one sun and one sky give every shadow edge on the ground the same step,
  so a second well-filled mode of log rho means edges of other kinds.
- **Too few profiles**: one stretch of edge decides the value.
- **Scattered evidence**: profiles that lie along one outline are one piece of evidence; a few
  profiles scattered over unrelated structures are weak evidence whatever their spread.
- **Outlines that disagree**: separate outlines of one shadow, and of all shadows on the ground,
  share the step; outlines whose medians differ are not all cast shadows.
- **Scattered dark sides**: the dark side of a cast shadow is one connected region; edges picked up
  on unrelated dark things each have a dark blob of their own.
"""

from __future__ import annotations

import math

from .evidence import EdgeEvidence
from .outcome import Verdict
from .rules import failed, few_profiles_warning  # the profile count rule is the fit's too

__all__ = ["SECOND_MODE_SHARE", "SECOND_MODE_MIN", "PROFILES_PER_STRUCTURE", "OUTLINE_DISAGREE_LOG",
           "OUTLINE_MIN_PROFILES", "OUTLINE_MIN_SHARE", "DARK_MAIN_MIN_PROFILES", "DARK_MAIN_SHARE",
           "judge_edges", "disagreement_warning", "outline_disagreement", "scattered_dark_sides", "nothing_measured"]

#: A second mode holding this share of the first's members (and at least SECOND_MODE_MIN profiles):
#: the edges disagree. On the real photo DSC_0569 the second mode held 11 profiles against 105
#: (paint); on the street preset a kerb's mode held 40 against the shadows' 43, and on other seeds
#: the shadows' mode was the smaller one.
SECOND_MODE_SHARE = 0.25
SECOND_MODE_MIN = 8
#: More separate structures than the kept profiles over this (and than 2): scattered evidence.
PROFILES_PER_STRUCTURE = 5
#: Separate outlines of at least OUTLINE_MIN_PROFILES kept profiles whose median log rho differ by more
#: than this disagree. On the street preset the kerb's outline read 0.27-0.29 against 0.32-0.34 on the
#: shadows of the same photo (0.15-0.2 in log); shadows near facades, which see less sky, read up to
#: 0.06 lower in log. Only outlines that each hold at least OUTLINE_MIN_SHARE of the kept profiles are
#: compared: on the real asphalt photo DSC_0569 outlines of 8 profiles scattered from 0.19 to 0.27
#: (texture, parking lines) while the two that held 63 of 105 read 0.228-0.229.
OUTLINE_DISAGREE_LOG = 0.12
OUTLINE_MIN_PROFILES = 4
OUTLINE_MIN_SHARE = 0.2
#: A dark region holding at least this many of the kept profiles' dark sides is a shadow. When less
#: than DARK_MAIN_SHARE of the profiles with a dark side fall in such regions, the evidence is scattered
#: over unrelated dark blobs (on the street preset and DSC_0569 the kept profiles' dark sides fall in
#: one or a few large regions).
DARK_MAIN_MIN_PROFILES = 3
DARK_MAIN_SHARE = 0.5


def disagreement_warning(modes: tuple[tuple[float, int], ...], measured_log: float) -> str:
    """The one "edges disagree" warning: the mode the reported rho comes from (``measured_log``)
    named first as "measured", then the fullest other mode; modes are (log peak, profiles), two or
    more. Named this way, the warning, the table's value and results.json's rho always agree on
    which mode was measured."""
    i = min(range(len(modes)), key=lambda j: abs(modes[j][0] - measured_log))
    other = next(m for j, m in enumerate(modes) if j != i)
    return (f"edges disagree: measured rho {math.exp(modes[i][0]):.3f} ({modes[i][1]} profiles), "
            f"another mode at rho {math.exp(other[0]):.3f} ({other[1]} profiles)")


def outline_disagreement(outlines: tuple[tuple[float, int], ...], n_kept: int) -> tuple[float, float] | None:
    """(lowest, highest) median log rho of the outlines (median log rho, profiles) that hold
    OUTLINE_MIN_SHARE of the ``n_kept`` profiles (and at least OUTLINE_MIN_PROFILES), when they differ
    by more than OUTLINE_DISAGREE_LOG; else None."""
    need = max(OUTLINE_MIN_PROFILES, OUTLINE_MIN_SHARE * n_kept)
    medians = [m for m, n in outlines if n >= need]
    if len(medians) < 2 or max(medians) - min(medians) <= OUTLINE_DISAGREE_LOG:
        return None
    return min(medians), max(medians)


def scattered_dark_sides(region_counts: tuple[int, ...]) -> str | None:
    """The warning for kept profiles whose dark sides lie scattered over many separate dark regions
    (``region_counts``: the dark sides each dark region holds), or None."""
    judged = sum(region_counts)
    if judged < DARK_MAIN_MIN_PROFILES:
        return None
    in_main = sum(c for c in region_counts if c >= DARK_MAIN_MIN_PROFILES)
    if in_main >= DARK_MAIN_SHARE * judged:
        return None
    return (f"dark sides scattered: {judged} profiles' dark sides lie in {len(region_counts)} separate dark "
            f"regions ({in_main} in regions of {DARK_MAIN_MIN_PROFILES}+), not one shadow")


def judge_edges(evidence: EdgeEvidence) -> Verdict:
    """The verdict of a single-photo measurement (module docstring); identifiable: no k is claimed."""
    warnings: list[str] = []
    modes = evidence.modes
    if len(modes) > 1 and modes[1][1] >= max(SECOND_MODE_SHARE * modes[0][1], SECOND_MODE_MIN):
        warnings.append(disagreement_warning(modes, evidence.measured_log))
    if few_profiles_warning(evidence.n_kept):
        warnings.append(few_profiles_warning(evidence.n_kept))
    if evidence.n_kept and evidence.n_structures > max(2, evidence.n_kept / PROFILES_PER_STRUCTURE):
        warnings.append(f"{evidence.n_kept} profiles spread over {evidence.n_structures} separate structures")
    spread = outline_disagreement(evidence.outlines, evidence.n_kept)
    if spread is not None:
        warnings.append(f"shadow outlines disagree: rho {math.exp(spread[0]):.3f} and {math.exp(spread[1]):.3f} "
                        "on separate outlines (an albedo edge, or ground that sees different sky)")
    if dark := scattered_dark_sides(evidence.dark_side_regions):
        warnings.append(dark)
    return Verdict(reliable=not warnings, identifiable=True, warnings=tuple(warnings))


def nothing_measured() -> Verdict:
    """The verdict of a photo in which no shadow edge was measured (no values)."""
    return failed()
