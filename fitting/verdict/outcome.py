"""What the rule book decides (``fitting.verdict.rules``): the values and errors as reported, and the
verdict on them. Frozen records; a result (``fitting.report.results.GroupResult``) is built from them."""

from __future__ import annotations

import dataclasses

__all__ = ["Estimate", "Verdict"]


@dataclasses.dataclass(frozen=True)
class Estimate:
    """k and rho with their one-sigma errors in physical units, as reported.

    range_k is an upper bound when the verdict says k is not identifiable. The stated errors
    (range_stderr, rho_stderr) are the statistical and systematic parts in quadrature
    (``fitting.solve.uncertainty``); None where there is no value (no geometry: no k).
    """

    range_k: float | None = None
    rho: float | None = None
    range_stderr: float | None = None
    rho_stderr: float | None = None
    range_stderr_stat: float | None = None
    rho_stderr_stat: float | None = None
    range_stderr_sys: float | None = None
    rho_stderr_sys: float | None = None


@dataclasses.dataclass(frozen=True)
class Verdict:
    """Whether the values can be trusted: ``reliable`` (False: a consistency check failed; the values
    are still given, but not their error bars), ``identifiable`` (False: k is not measured and
    range_k is an upper bound) and one-line ``warnings`` (the reasons, and notes for the user)."""

    reliable: bool
    identifiable: bool
    warnings: tuple[str, ...] = ()
