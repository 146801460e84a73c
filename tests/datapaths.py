"""Where the tests find real data.

- ``VENDORED``: tests/data, files whose licences allow redistribution, kept in the
  repository with a licence line beside each (tests/data/README.md).
- ``WORKSPACE``: ../shared/data beside the repository, the development workspace's
  real photos and RAW files whose licences forbid copying them here. Tests that
  read it skip with a clear message when it is absent (as in a fresh clone and CI).
"""

from __future__ import annotations

from pathlib import Path

VENDORED = Path(__file__).resolve().parent / "data"
MITSUBA = VENDORED / "mitsuba"
WORKSPACE = Path(__file__).resolve().parents[2] / "shared" / "data"
