"""Shared test fixtures. Tests never read ../shared: the sample data lives in tests/data."""
from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest

os.environ.setdefault("HF_HUB_OFFLINE", "1")
os.environ.setdefault("TRANSFORMERS_OFFLINE", "1")
os.environ.setdefault("VTK_DEFAULT_OPENGL_WINDOW", "vtkEGLRenderWindow")
os.environ.setdefault("MPLBACKEND", "Agg")

DATA_DIR = Path(__file__).parent / "data"
SAMPLE_DIR = DATA_DIR / "humanml3d_sample"


@pytest.fixture(scope="session")
def sample_dir() -> Path:
    return SAMPLE_DIR


@pytest.fixture(scope="session")
def sample_features() -> np.ndarray:
    """Real HumanML3D features of motion 012314, ``(N-1, 263)``."""
    return np.load(SAMPLE_DIR / "new_joint_vecs" / "012314.npy")


@pytest.fixture(scope="session")
def sample_joints() -> np.ndarray:
    """Real HumanML3D joints of motion 012314 (recovered from the features), ``(N-1, 22, 3)``."""
    return np.load(SAMPLE_DIR / "new_joints" / "012314.npy")
