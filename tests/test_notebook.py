"""Executes notebooks/quickstart.ipynb end to end (small config) so it cannot rot."""

import os

import nbformat
import pytest
from helpers import REPO
from nbclient import NotebookClient


@pytest.mark.slow  # ~3 min alone (every cell, two compiles): make test-slow
def test_quickstart_notebook_runs(tmp_path):
    path = os.path.join(REPO, "notebooks", "quickstart.ipynb")
    nb = nbformat.read(path, as_version=4)
    client = NotebookClient(
        nb, timeout=900, kernel_name="python3", resources={"metadata": {"path": REPO}}
    )
    client.execute()
    outputs = [o for c in nb.cells if c.cell_type == "code" for o in c.get("outputs", [])]
    assert not [o for o in outputs if o.get("output_type") == "error"]
    text = "".join(o.get("text", "") for o in outputs if o.get("output_type") == "stream")
    assert "observation sizes" in text
    assert "it 3/3" in text  # the trainer printed its third iteration
