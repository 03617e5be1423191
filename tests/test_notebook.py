"""The quick-start notebook runs top to bottom on the C backend (documentation must not rot)."""

from pathlib import Path

import nbformat
from nbclient import NotebookClient

NOTEBOOK = Path(__file__).parent.parent / "notebooks" / "quickstart.ipynb"


def test_quickstart_notebook_runs(tmp_path, gl):
    nb = nbformat.read(NOTEBOOK, as_version=4)
    client = NotebookClient(
        nb, timeout=600, kernel_name="python3", resources={"metadata": {"path": str(tmp_path)}}
    )
    client.execute()
    outputs = [o for c in nb.cells if c.cell_type == "code" for o in c.outputs]
    assert not [o for o in outputs if o.output_type == "error"]
    text = "".join(o.get("text", "") for o in outputs if o.output_type == "stream")
    assert "tabletop_push/scripted on c: success" in text and "episodes" in text
    assert "same episode as evaluated" in text
    tables = [o for o in outputs if "text/markdown" in o.get("data", {})]
    assert len(tables) == 2 and "| goal_distance |" in tables[1]["data"]["text/markdown"]
    pngs = [o for o in outputs if "image/png" in o.get("data", {})]
    assert len(pngs) == 3  # two plots and a video frame
    assert list(tmp_path.iterdir()) == []  # it writes no files
