"""Packaging: licence, citation, typed packages, the extras and their one-line messages."""

from __future__ import annotations

import importlib.util
import tomllib
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("softshadow", "scene", "fitting", "data_synth", "softshadow_cli")


def _pyproject() -> dict:
    return tomllib.loads((ROOT / "pyproject.toml").read_text())


def test_licence_and_citation():
    project = _pyproject()["project"]
    assert project["license"] == "MIT" and "MIT License" in (ROOT / "LICENSE").read_text()
    citation = (ROOT / "CITATION.cff").read_text()
    assert "cff-version:" in citation and "Shoji" in citation and "Dowling" in citation
    from softshadow import __version__
    assert f"version: {__version__}" in citation


@pytest.mark.parametrize("package", PACKAGES)
def test_packages_are_typed(package):
    assert (ROOT / package / "py.typed").is_file()


def test_benchmarks_are_not_installed():
    find = _pyproject()["tool"]["setuptools"]["packages"]["find"]["include"]
    assert not any(p.startswith("benchmarks") for p in find)


def test_dask_is_an_extra_named_when_missing(monkeypatch, tmp_path):
    project = _pyproject()["project"]
    assert not any(d.startswith("dask") for d in project["dependencies"])
    assert any(d.startswith("dask") for d in project["optional-dependencies"]["many"])
    from fitting import fit_many
    real = importlib.util.find_spec
    monkeypatch.setattr(importlib.util, "find_spec", lambda name, *a: None if name == "distributed" else real(name, *a))
    with pytest.raises(ValueError, match=r"pip install 'softshadow\[many\]'"):
        fit_many(tmp_path, tmp_path / "out")
