"""Shared test set-up: float64 JAX and the hypothesis profiles.

- JAX runs in float64 for the whole session: the renderer's gradient checks
  compare autodiff with central finite differences, which float32 cannot
  resolve. This must happen before any JAX array is created, hence here. The
  float32 path that the command line uses is tested inside
  ``jax.enable_x64(False)`` scopes (tests/test_float32.py).
- Hypothesis profiles (docs/testing.md): ``ci`` (20 derandomised examples, no
  deadline: JAX compiles on the first example; no shrinking) is chosen when the
  environment variable CI is set; ``dev`` (50 random examples, with shrinking)
  otherwise; ``long`` (500 examples) for a thorough local run.
  HYPOTHESIS_PROFILE overrides the choice.
- Compiled JAX executables are dropped after any test that leaves the process holding more than
  ``_MAPS_LIMIT`` memory maps: XLA's CPU backend maps memory for every executable it JIT-compiles
  and keeps each one while its cache does, and the whole suite compiles thousands (one per shape,
  static argument and transformation). Past the kernel's ``vm.max_map_count`` (65530 by default)
  the next compile fails inside XLA with a segmentation fault. Dropping them only then keeps the
  executables that later modules reuse (a compile costs seconds).
"""

from __future__ import annotations

import gc
import os

import jax
import pytest

jax.config.update("jax_enable_x64", True)

from hypothesis import HealthCheck, Phase, settings  # noqa: E402  (after the JAX switch, on purpose)

_SLOW_OK = [HealthCheck.too_slow, HealthCheck.data_too_large]

# CI: no shrinking (a failure is reported as found; shrinking a renderer scene takes minutes).
# 20 examples: the property tests' examples share one compiled evaluation each (fixed shapes,
# tests/gradcheck.py), so after the first example each costs a plan and a few evaluations.
settings.register_profile("ci", max_examples=20, deadline=None, derandomize=True,
                          phases=(Phase.explicit, Phase.reuse, Phase.generate),
                          suppress_health_check=_SLOW_OK, print_blob=True)
settings.register_profile("dev", max_examples=50, deadline=None,
                          suppress_health_check=_SLOW_OK, print_blob=True)
settings.register_profile("long", max_examples=500, deadline=None,
                          suppress_health_check=_SLOW_OK, print_blob=True)
settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE") or ("ci" if os.environ.get("CI") else "dev"))


# A third of the kernel's default vm.max_map_count; the most any one test adds is ~3,600 maps.
_MAPS_LIMIT = 20_000


def _memory_maps() -> int:
    """The number of this process's memory maps (0 where /proc is missing)."""
    try:
        with open("/proc/self/maps", "rb") as maps:
            return sum(1 for _ in maps)
    except OSError:
        return 0


def _drop_compiled() -> None:
    jax.clear_caches()
    gc.collect()  # the executables go when the last reference does


@pytest.hookimpl(trylast=True)
def pytest_runtest_teardown(item, nextitem):
    if _memory_maps() > _MAPS_LIMIT:
        _drop_compiled()
