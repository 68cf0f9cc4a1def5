"""Markers of the tests that need the shipped weights (imported as ``from _weights import needs_weights``)."""
from __future__ import annotations

import pytest

from salad_core.pipeline import default_weights_dir

#: Skips a test unless the shipped SALAD pipeline (``salad_core/weights/salad``) is there.
needs_weights = pytest.mark.skipif(not (default_weights_dir() / "pipeline.json").is_file(),
                                   reason="needs the shipped SALAD weights (salad_core/weights/salad)")
