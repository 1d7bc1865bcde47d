"""The walkthrough notebook runs top to bottom on the current interpreter and worktree."""

from __future__ import annotations

import json
import sys

import pytest
from conftest import ROOT

nbformat = pytest.importorskip("nbformat")
nbclient = pytest.importorskip("nbclient")
pytest.importorskip("ipykernel")

NOTEBOOK = ROOT / "notebooks" / "walkthrough.ipynb"


@pytest.fixture
def kernel_env(tmp_path, monkeypatch):
    """A `python3` kernelspec for this interpreter, found first, importing this worktree."""
    spec = tmp_path / "kernels" / "python3"
    spec.mkdir(parents=True)
    (spec / "kernel.json").write_text(
        json.dumps(
            {
                "argv": [sys.executable, "-m", "ipykernel_launcher", "-f", "{connection_file}"],
                "display_name": "Python 3 (tests)",
                "language": "python",
                "env": {"PYTHONPATH": str(ROOT), "MPLBACKEND": "Agg"},
            }
        )
    )
    monkeypatch.setenv("JUPYTER_PATH", str(tmp_path))
    return tmp_path


def test_notebook_is_stored_without_outputs():
    nb = nbformat.read(NOTEBOOK, as_version=4)
    for cell in nb.cells:
        if cell.cell_type == "code":
            assert cell.outputs == [] and cell.execution_count is None


@pytest.mark.slow
def test_walkthrough_executes(kernel_env):
    nb = nbformat.read(NOTEBOOK, as_version=4)
    client = nbclient.NotebookClient(
        nb,
        kernel_name="python3",
        timeout=120,
        resources={"metadata": {"path": str(ROOT / "notebooks")}},
    )
    client.execute()
    text = "\n".join(
        out.get("text", "") + json.dumps(out.get("data", {}).get("text/plain", ""))
        for cell in nb.cells
        if cell.cell_type == "code"
        for out in cell.outputs
    )
    # 19 events, two findings (the demo's SDO abort and EMCY: load() runs the checks) and
    # the boot story of each of the sample's 3 nodes (kind `boot`)
    assert "185 frames, 24 events, 7 SDO transactions" in text
    assert "Object does not exist in the object dictionary" in text  # the SDO table
    assert "operational" in text  # nodes table
    hb = next(c for c in nb.cells if "hb_stats" in c.source)
    table = hb.outputs[0]["data"]["text/plain"].splitlines()
    rows = {line.split()[0]: line.split()[1:] for line in table[2:]}
    assert set(rows) == {"3", "5"}  # node 10 is guarded, it sends no heartbeat
    for count, mean, *_ in rows.values():
        assert float(count) == 19 and abs(float(mean) - 100.0) < 0.01  # 100 ms producer time
    errors = [
        o for c in nb.cells if c.cell_type == "code" for o in c.outputs if o.output_type == "error"
    ]
    assert errors == []
