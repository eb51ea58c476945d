"""examples/story.ipynb runs top to bottom: every cell, its `assert`s included, without an error.

Executed with nbclient on the kernel of this interpreter (the project's .venv, with the
shear_twin package installed: scripts/install-python-package.sh), in a temporary working
directory, its files in a temporary directory too; the executed notebook is kept in memory
and never written back, so the committed one stays without outputs. Needs the FMUs and the
release `twin` (scripts/build-fmus.sh).
"""

from __future__ import annotations

from pathlib import Path

import nbformat
from nbclient import NotebookClient
from nbclient.exceptions import CellExecutionError

REPO = Path(__file__).resolve().parents[2]
NOTEBOOK = REPO / "examples" / "story.ipynb"


def test_the_story_notebook_runs_and_its_claims_hold(tmp_path, monkeypatch):
    notebook = nbformat.read(NOTEBOOK, as_version=4)
    # Committed without outputs: an executed notebook checked in would show stale numbers.
    assert all(not c.get("outputs") for c in notebook.cells if c.cell_type == "code")
    work = tmp_path / "cwd"
    work.mkdir()
    monkeypatch.setenv("SHEAR_TWIN_ROOT", str(REPO))
    monkeypatch.setenv("SHEAR_TWIN_OUT", str(tmp_path / "out"))
    # "python3": ipykernel's kernel, which jupyter_client starts with this interpreter (the venv).
    client = NotebookClient(notebook, timeout=600, kernel_name="python3",
                            resources={"metadata": {"path": str(work)}})
    try:
        client.execute()
    except CellExecutionError as error:
        raise AssertionError(f"{NOTEBOOK.name}: a cell failed:\n{error}") from None
    code = [c for c in notebook.cells if c.cell_type == "code"]
    assert all(c.execution_count is not None for c in code)
    # The plots are inline: every figure the notebook draws is in its outputs as a PNG.
    images = sum(1 for c in code for o in c.outputs if "image/png" in o.get("data", {}))
    assert images >= 6, images
    assert (tmp_path / "out" / "with-contact.ssp").is_file()  # its files went where it was told
