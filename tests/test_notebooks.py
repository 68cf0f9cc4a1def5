"""Every notebook runs headless in QUICK mode (the default) and fails the build if a cell fails.

The committed notebooks are the source (see ``notebooks/README.md``); how they are stored (no
outputs, the parameters cell, lint) is checked by ``tests/test_notebook_sources.py``. Each runs with
its own folder as the working directory, as in JupyterLab, and writes only under a temporary
``SALAD_NOTEBOOK_OUT``.

Environment: ``SALAD_NOTEBOOK_KEEP=DIR`` writes each executed notebook (with outputs) to ``DIR`` for
inspection; ``SALAD_NOTEBOOK_MAX_SECONDS=S`` fails a notebook that takes longer than ``S`` seconds
(QUICK mode's budget is about 120 s each on a 2-core CPU; unset: no limit, as machines differ).

A notebook that writes numbers a reader is told to trust has them checked after it ran (:data:`OUTPUT_CHECKS`).
"""
from __future__ import annotations

import json
import os
import time
from pathlib import Path

import pytest

NOTEBOOKS = sorted((Path(__file__).resolve().parents[1] / "notebooks").glob("*.ipynb"))
#: How far (cm, root-aligned) an edit of a take may move what it keeps: the documented bound of MirrorTake's and
#: Inpaint's composite (``lab/docs/editing.md``).
KEPT_CM = 2.0


def _check_real_motion_take_edits(out: Path) -> None:
    """Notebook 10's edits of its own takes (``real_motion_take_edits.json``): MirrorTake keeps the joints outside
    the mirrored limbs within :data:`KEPT_CM` and, on the one-sided DeepMimic punch (when pybullet is installed),
    swaps the side that leads; every grounded edit's pelvis stays under its ceiling; in-painting keeps the kept
    joints within :data:`KEPT_CM`."""
    record = json.loads((out / "real_motion_take_edits.json").read_text(encoding="utf-8"))
    take = record["mirror_take"]
    assert take["kept_cm"] < KEPT_CM, f"MirrorTake({take['parts']}) moved the rest of the take: {take}"
    if take["take"].startswith("DeepMimic"):
        assert take["before"] * take["after"] < 0, f"MirrorTake({take['parts']}) did not swap the leading side: {take}"
    for label, run in record["grounding"]["runs"].items():
        if run["ceiling"] is not None:
            assert run["pelvis_max"] <= run["ceiling"] + 1e-3, f"{label}: the pelvis is above the ceiling: {run}"
    for label, run in record["inpaint"].items():
        assert run["kept, root-aligned (cm)"] < KEPT_CM, f"{label} moved what it keeps: {run}"


#: Checks of a notebook's written outputs after it ran (by notebook stem; the argument is its SALAD_NOTEBOOK_OUT).
OUTPUT_CHECKS = {"10_real_motion": _check_real_motion_take_edits}


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
    if path.stem in OUTPUT_CHECKS:
        OUTPUT_CHECKS[path.stem](tmp_path)
    budget = os.environ.get("SALAD_NOTEBOOK_MAX_SECONDS")
    if budget:
        assert seconds <= float(budget), f"{path.name} took {seconds:.0f} s in QUICK mode (budget {budget} s)"
