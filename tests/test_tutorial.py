"""The tutorial notebook (docs/tutorial.ipynb, shown in the docs site) runs from top to bottom."""

from __future__ import annotations

from pathlib import Path

import nbclient
import nbformat

ROOT = Path(__file__).resolve().parents[1]


def test_tutorial_notebook_runs(tmp_path):
    nb = nbformat.read(ROOT / "docs" / "tutorial.ipynb", as_version=4)
    nbclient.NotebookClient(nb, timeout=900, kernel_name="python3",
                            resources={"metadata": {"path": str(tmp_path)}}).execute()
    text = "".join(o.get("text", "") for c in nb.cells if c.cell_type == "code" for o in c.get("outputs", []))
    assert "Range of the soft shadow" in text and "d(darkness)/dk: autodiff" in text
    auto, central = (float(v) for v in text.split("autodiff ")[1].split(", central difference "))
    assert abs(auto - central) <= 0.02 * abs(central)
