"""Every notebook runs headless in QUICK mode (the default) and fails the build if a cell fails.

The committed notebooks are the source (see ``notebooks/README.md``); how they are stored (no
outputs, the parameters cell, lint) is checked by ``tests/test_notebook_sources.py``. Each runs with
its own folder as the working directory, as in JupyterLab, and writes only under a temporary
``SALAD_NOTEBOOK_OUT``.

Environment: ``SALAD_NOTEBOOK_KEEP=DIR`` writes each executed notebook (with outputs) to ``DIR`` for
inspection; ``SALAD_NOTEBOOK_MAX_SECONDS=S`` fails a notebook that takes longer than ``S`` seconds
(QUICK mode's budget is about 120 s each on a 2-core CPU; unset: no limit, as machines differ).
"""
from __future__ import annotations

import os
import time
from pathlib import Path

import pytest

NOTEBOOKS = sorted((Path(__file__).resolve().parents[1] / "notebooks").glob("*.ipynb"))


@pytest.mark.notebooks
@pytest.mark.parametrize("path", NOTEBOOKS, ids=[p.stem for p in NOTEBOOKS])
def test_notebook_runs_in_quick_mode(path, tmp_path, monkeypatch):
    import nbformat
    from nbclient import NotebookClient

    nb = nbformat.read(path, as_version=4)
    # the kernel inherits this process's environment
    monkeypatch.setenv("SALAD_QUICK", "1")
    monkeypatch.setenv("SALAD_NOTEBOOK_OUT", str(tmp_path))
    client = NotebookClient(nb, timeout=600, kernel_name="python3",
                            resources={"metadata": {"path": str(path.parent)}})
    t0 = time.perf_counter()
    try:
        client.execute()
    finally:
        seconds = time.perf_counter() - t0
        keep = os.environ.get("SALAD_NOTEBOOK_KEEP")
        if keep:
            Path(keep).mkdir(parents=True, exist_ok=True)
            nbformat.write(nb, Path(keep) / path.name)
    print(f"{path.name}: {seconds:.1f} s")
    errors = [o for c in nb.cells if c.cell_type == "code" for o in c.get("outputs", [])
              if o.get("output_type") == "error"]
    assert not errors
    budget = os.environ.get("SALAD_NOTEBOOK_MAX_SECONDS")
    if budget:
        assert seconds <= float(budget), f"{path.name} took {seconds:.0f} s in QUICK mode (budget {budget} s)"
