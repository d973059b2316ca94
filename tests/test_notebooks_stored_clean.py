"""Notebooks are committed without outputs (the suite executes them through nbmake)."""

import json

from tests.helpers import REPO


def test_notebooks_have_no_outputs():
    notebooks = sorted((REPO / "notebooks").glob("*.ipynb"))
    assert [n.name for n in notebooks] == [
        "lyman_alpha_analysis.ipynb",
        "vis_532nm_validation.ipynb",
        "where_to_measure_next.ipynb",
    ]
    for notebook in notebooks:
        for cell in json.loads(notebook.read_text())["cells"]:
            if cell["cell_type"] == "code":
                assert cell["outputs"] == [] and cell["execution_count"] is None, notebook.name
