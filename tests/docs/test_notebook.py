"""demos/first_model.py executed as a Jupyter notebook (jupytext pair, nbclient, ipykernel) at a
tiny size: every cell runs, the pictures come out inline as PNGs, and what the text says holds."""

from __future__ import annotations

import base64
import os
import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
DEMO = ROOT / "demos" / "first_model.py"

jupytext = pytest.importorskip("jupytext")
nbclient = pytest.importorskip("nbclient")


def _outputs(notebook, kind: str) -> list:
    return [out for cell in notebook.cells if cell.cell_type == "code" for out in cell.get("outputs", [])
            if kind in out.get("data", {}) or out.get("output_type") == kind]


def test_first_model_notebook_executes_with_inline_pictures(tmp_path, monkeypatch):
    notebook = jupytext.read(DEMO)
    assert sum(cell.cell_type == "markdown" for cell in notebook.cells) >= 5
    out = tmp_path / "out"
    monkeypatch.setenv("PIC_DEMO_SIZE", "tiny")
    monkeypatch.setenv("PIC_DEMO_OUTPUT", str(out))
    monkeypatch.setenv("MPLBACKEND", "module://matplotlib_inline.backend_inline")
    client = nbclient.NotebookClient(notebook, timeout=900, kernel_name="python3",
                                     resources={"metadata": {"path": str(tmp_path)}})
    client.execute()

    assert not _outputs(notebook, "error")
    pictures = _outputs(notebook, "image/png")
    assert len(pictures) >= 2, "the statistics plot and the pyvista picture are shown inline"
    keep = Path(os.environ.get("PIC_NOTEBOOK_PNG_DIR", tmp_path))
    keep.mkdir(parents=True, exist_ok=True)
    for i, picture in enumerate(pictures):
        data = base64.b64decode(picture["data"]["image/png"])
        assert data[:8] == b"\x89PNG\r\n\x1a\n" and len(data) > 10_000
        (keep / f"first_model_{i}.png").write_bytes(data)

    text = "".join(out.get("text", "") for out in _outputs(notebook, "stream"))
    steps = re.search(r"(\d+) steps to t = ([\d.]+): (.+)", text)
    assert steps and int(steps.group(1)) >= 2 and float(steps.group(2)) == pytest.approx(0.06)
    last = re.search(r"last step: vrms = ([\d.]+), Nu = ([\d.]+)", text)
    assert last and 0.0 < float(last.group(1)) < 100.0 and 0.9 < float(last.group(2)) < 6.0
    assert re.search(r"t = [\d.]+: 128 cells, 2560 particles", text)
    heights = re.search(r"highest particles: ([\d.]+) at the left, ([\d.]+) at the right", text)
    assert heights and float(heights.group(1)) > float(heights.group(2)), "lifted at the left first"
    # the loop of one's own: three finite steps with the flow speeding up
    loop = [float(v) for _, v in re.findall(r"t = ([\d.]+)  vrms = ([\d.]+)", text)]
    assert len(loop) == 3 and loop[0] < loop[1] < loop[2]
    for name in ("statistics.csv", "fields.xdmf", "particles.xdmf", "first_model.png"):
        assert (out / name).is_file()
