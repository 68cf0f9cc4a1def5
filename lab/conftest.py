"""The lab's tests (``.venv/bin/python -m pytest -q lab/tests``): ``lab/`` on ``sys.path`` for ``salad_lab``, and
the toolkit's shared test fixtures and helpers (``tests/conftest.py``, ``tests/_doubles.py``), which the lab may use.
The dependency goes one way: the lab imports the toolkit and its test helpers, the toolkit never imports the lab."""
from __future__ import annotations

import importlib.util
import sys
from pathlib import Path

LAB = Path(__file__).resolve().parent
REPO = LAB.parent
for path in (LAB, REPO / "tests"):
    if str(path) not in sys.path:
        sys.path.insert(0, str(path))

# the toolkit's fixtures (sample data, tiny pipelines, the tiny corpus, the recording python), by name
_spec = importlib.util.spec_from_file_location("_toolkit_conftest", REPO / "tests" / "conftest.py")
_toolkit = importlib.util.module_from_spec(_spec)
sys.modules["_toolkit_conftest"] = _toolkit
_spec.loader.exec_module(_toolkit)
for _name in ("sample_dir", "sample_features", "sample_joints", "single_thread", "make_tiny_pipeline", "pipe",
              "tiny_procedural_corpus", "tiny_random_evaluator", "recorder"):
    globals()[_name] = getattr(_toolkit, _name)
