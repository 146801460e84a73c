"""``softshadow demo``'s verdict line (the demo itself runs as the README says, in tests/test_readme.py)."""

from __future__ import annotations

from fitting import FitResults, GroupResult
from softshadow_cli.demo_command import demo_verdict

TRUTH = {"groups": [{"label": "09:20", "photos": ["a.jpg"], "range_k": 0.0056, "rho": 0.157},
                    {"label": "13:21", "photos": ["b.jpg"], "range_k": 0.0052, "rho": 0.190},
                    {"label": "16:21", "photos": ["c.jpg"], "range_k": 0.0073, "rho": 0.465}]}


def _g(label, photo, k, k_err, rho, rho_err, **kw):
    return GroupResult.from_json(dict(label=label, time=label, photos=[photo], range_k=k, range_stderr=k_err, rho=rho,
                                      rho_stderr=rho_err, converged=True, **kw))


def test_verdict_counts_groups_within_two_stated_errors():
    results = FitResults([_g("09:21", "a.jpg", 0.0060, 0.0004, 0.150, 0.004),
                          _g("13:22", "b.jpg", 0.0050, 0.0004, 0.210, 0.004),  # rho 5 errors off
                          _g("16:22", "c.jpg", 0.0090, 0.0010, 0.47, 0.006, identifiable=False)], [], {})
    line = demo_verdict(results, TRUTH)
    assert line.startswith("verdict: k and ρ within two stated errors of the truth in 2 of 3 groups")
    assert "13:22: ρ 5.0 stated errors off" in line


def test_verdict_names_a_bound_under_the_truth_and_a_failed_group():
    results = FitResults([_g("09:21", "a.jpg", 0.0040, 0.0004, 0.157, 0.004, identifiable=False),
                          GroupResult.failed("13:22", "13:22", ["b.jpg"], "no shadow in view")], [], {})
    line = demo_verdict(results, TRUTH)
    assert "in 0 of 2 groups" in line and "bound 0.004 under the truth" in line and "not fitted" in line
