"""Shared test set-up: float64 JAX and the hypothesis profiles.

- JAX runs in float64 for the whole session: the renderer's gradient checks
  compare autodiff with central finite differences, which float32 cannot
  resolve. This must happen before any JAX array is created, hence here.
- Hypothesis profiles: ``ci`` (few examples, no deadline: JAX compiles on the
  first example) is chosen when the environment variable CI is set; ``dev``
  (more examples, with shrinking) otherwise. HYPOTHESIS_PROFILE overrides both.
"""

from __future__ import annotations

import os

import jax

jax.config.update("jax_enable_x64", True)

from hypothesis import HealthCheck, Phase, settings  # noqa: E402  (after the JAX switch, on purpose)

_SLOW_OK = [HealthCheck.too_slow, HealthCheck.data_too_large]

# CI: no shrinking (a failure is reported as found; shrinking a renderer scene takes minutes).
settings.register_profile("ci", max_examples=4, deadline=None, derandomize=True,
                          phases=(Phase.explicit, Phase.reuse, Phase.generate),
                          suppress_health_check=_SLOW_OK, print_blob=True)
settings.register_profile("dev", max_examples=12, deadline=None,
                          suppress_health_check=_SLOW_OK, print_blob=True)
settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE") or ("ci" if os.environ.get("CI") else "dev"))
