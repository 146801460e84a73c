"""The fit's options (``FitOptions``), apart from the solver so that reading them loads no JAX."""

from __future__ import annotations

import dataclasses
from typing import Literal

__all__ = ["FitOptions", "sampling_rule"]


@dataclasses.dataclass
class FitOptions:
    """Choices of the fit. profiles / blur: candidates compared by BIC.

    The default profile is ``disk``: the sun is a disk, and with it k reads tan(sun radius),
    the truth convention of docs/formats.md and the Mitsuba renders. ("linear", "disk") lets BIC
    choose; a linear ramp fitted to a real sun reads about 0.854 of that k.
    """

    profiles: tuple[Literal["linear", "disk"], ...] = ("disk",)
    blur: tuple[bool, ...] = (False, True)
    # The penumbra's rule: "edge" (the ramp about the nearest silhouette edge), "paper" (the seed's
    # expanded volume), "wedge" (the sun's hidden fraction), or "auto": "edge", refitted with "wedge"
    # where the two differ by more than the photos' noise (``fitting.solve.rule_choice``).
    rule: Literal["edge", "paper", "wedge", "auto"] = "edge"
    range_k_max: float = 0.03
    max_samples_per_photo: int = 1300  # three photos fill a 4,096 bucket
    robust: bool = True
    max_steps: int = 60
    seed: int = 0
    sky_occlusion: bool = True  # model the sky the object hides from each sample (softshadow.sky)
    plots: bool = True
    overlays: Literal["first", "all", "none"] = "first"  # overlay plots for the "first" photo of each group, "all", or "none"
    verbose: bool = False
    # Level of detail of the object's mesh (``fitting.solve.lod``): "auto" (the coarsest level that moves
    # k and rho by at most lod_tolerance of their stated standard errors), "off" (the mesh as it is), or
    # a face count (that level, decimated).
    lod: Literal["auto", "off"] | int = "auto"
    lod_tolerance: float = 0.1


def sampling_rule(rule: str) -> Literal["edge", "paper"]:
    """The rule of the model the samples are drawn (and the plan's nearest edges chosen) with: the
    ``wedge`` and ``auto`` fits draw them as the ``edge`` rule does."""
    return "paper" if rule == "paper" else "edge"
