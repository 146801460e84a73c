"""OpenMP's idle threads sleep: ``import softshadow`` sets ``OMP_WAIT_POLICY=PASSIVE`` before any
parallel loop starts numba's OpenMP threads, and warns when they started before without it
(``softshadow.parallel_loops``). Each case runs in a fresh interpreter: OpenMP reads the setting
once per process."""

from __future__ import annotations

import json
import os
import subprocess
import sys

import pytest

# A parallel loop of the user's, run before or after ``import softshadow``; prints the policy the
# process ends with, numba's threading layer and the warnings of the import.
_PROGRAM = """
import json, os, sys, warnings
import numba

@numba.njit(parallel=True)
def user_loop(n):
    s = 0
    for i in numba.prange(n):
        s += i
    return s

with warnings.catch_warnings(record=True) as caught:
    warnings.simplefilter("always")
    if sys.argv[1] == "loop_first":
        user_loop(10)
    import softshadow
    user_loop(10)
print(json.dumps({"policy": os.environ.get("OMP_WAIT_POLICY"), "layer": numba.threading_layer(),
                  "warnings": [str(w.message) for w in caught if issubclass(w.category, RuntimeWarning)]}))
"""


def _run(order: str, policy: str | None) -> dict:
    env = {k: v for k, v in os.environ.items() if k != "OMP_WAIT_POLICY"}
    if policy is not None:
        env["OMP_WAIT_POLICY"] = policy
    out = subprocess.run([sys.executable, "-c", _PROGRAM, order], env=env, capture_output=True, text=True,
                         timeout=300)
    assert out.returncode == 0, out.stderr
    result = json.loads(out.stdout.strip().splitlines()[-1])
    if result["layer"] != "omp":
        pytest.skip(f"numba's threading layer here is {result['layer']!r}, not OpenMP")
    return result


def test_import_sets_the_policy_before_a_users_loop():
    result = _run("import_first", None)
    assert result["policy"] == "PASSIVE" and result["warnings"] == []


def test_openmp_started_before_the_import_is_reported():
    result = _run("loop_first", None)
    assert result["policy"] == "PASSIVE"
    assert len(result["warnings"]) == 1 and "OMP_WAIT_POLICY=PASSIVE" in result["warnings"][0]


def test_a_policy_set_by_the_user_wins_and_is_not_reported():
    result = _run("loop_first", "ACTIVE")
    assert result["policy"] == "ACTIVE" and result["warnings"] == []
