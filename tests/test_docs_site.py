"""The documentation site builds with ``mkdocs build --strict`` (every page in the navigation, no broken link,
the API reference from the docstrings)."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def test_mkdocs_builds_strict(tmp_path):
    env = {**os.environ, "NO_MKDOCS_2_WARNING": "1"}
    out = subprocess.run([sys.executable, "-m", "mkdocs", "build", "--strict", "--site-dir", str(tmp_path / "site")],
                         cwd=ROOT, capture_output=True, text=True, env=env, timeout=600)
    assert out.returncode == 0, out.stdout[-3000:] + out.stderr[-3000:]
    api = (tmp_path / "site" / "api" / "softshadow" / "index.html").read_text()
    assert "SoftShadowModel" in api and "fit_folder" in (tmp_path / "site" / "api" / "fitting" / "index.html").read_text()
