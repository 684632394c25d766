"""Every notebook in notebooks/ runs top to bottom in reduced mode."""

from pathlib import Path

import nbformat
import pytest
from nbclient import NotebookClient

NOTEBOOKS = sorted((Path(__file__).resolve().parent.parent / "notebooks").glob("*.ipynb"))


@pytest.mark.parametrize("path", NOTEBOOKS, ids=[p.stem for p in NOTEBOOKS])
def test_notebook_runs(path, tmp_path, monkeypatch):
    monkeypatch.setenv("HANDLE_DRAKE_REDUCED", "1")
    monkeypatch.setenv("HANDLE_DRAKE_OUT", str(tmp_path))
    notebook = nbformat.read(path, as_version=4)
    client = NotebookClient(notebook, timeout=600, kernel_name="python3",
                            resources={"metadata": {"path": str(tmp_path)}})
    client.execute()


def test_there_are_notebooks():
    assert NOTEBOOKS, "notebooks/ must hold one notebook per capability"


@pytest.mark.parametrize("path", NOTEBOOKS, ids=[p.stem for p in NOTEBOOKS])
def test_notebook_is_committed_without_outputs(path):
    """A run in Jupyter leaves outputs and counts in the file: clear them before committing
    (Jupyter: Edit > Clear Outputs of All Cells; or `jupyter nbconvert --clear-output
    --inplace notebooks/*.ipynb`)."""
    notebook = nbformat.read(path, as_version=4)
    dirty = [i for i, cell in enumerate(notebook.cells) if cell.cell_type == "code"
             and (cell.get("outputs") or cell.get("execution_count") is not None)]
    assert not dirty, f"{path.name}: code cells {dirty} have outputs or execution counts"


def test_what_a_newcomer_creates_is_ignored_by_git():
    """The README's virtual environment and what the notebooks write beside themselves."""
    import shutil
    import subprocess

    root = NOTEBOOKS[0].parent.parent
    if shutil.which("git") is None or not (root / ".gitignore").is_file():
        pytest.skip("not a git checkout")
    paths = [".venv/bin/python", "notebooks/station_grasp.png", "notebooks/01_scene.html",
             "notebooks/babbling_notebook.sqlite", "out/demo.html"]
    result = subprocess.run(["git", "check-ignore", "--no-index", *paths], cwd=root,
                            capture_output=True, text=True)
    assert sorted(result.stdout.split()) == sorted(paths)
    kept = subprocess.run(["git", "check-ignore", "--no-index", "notebooks/00_station.ipynb"],
                          cwd=root, capture_output=True, text=True)
    assert kept.returncode == 1  # the notebooks themselves are not ignored
