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
# the test process keeps glibc's allocator: the salad command would otherwise tune it for the whole
# session (salad_core.allocator), and tests measure memory growth
os.environ.setdefault("SALAD_ALLOCATOR", "system")
# the OpenMP wait policy as the salad command chooses it, before any test imports torch (importing salad_core
# changes nothing in the process; salad_core.openmp)
from salad_core import openmp as _openmp  # noqa: E402

_openmp.configure()

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


@pytest.fixture(scope="module")
def single_thread():
    """Run a module's tests with one torch thread (tiny models are dominated by thread hand-off,
    and one thread is immune to other processes loading the 2 cores); restores the setting."""
    import torch

    before = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(before)


@pytest.fixture(scope="session")
def make_tiny_pipeline(sample_dir):
    """Factory of tiny randomly initialised pipelines: the real VAE, a 3-layer width-32 denoiser,
    the real MiniLM and the sample's Mean/Std (fast; the motions are noise, the plumbing is real)."""
    def make(seed: int = 0):
        import torch

        from salad_core.models import Denoiser, DenoiserConfig, MotionVAE, VAEConfig
        from salad_core.pipeline import SaladPipeline
        from salad_core.text import load_text_encoder

        torch.manual_seed(seed)
        vae = MotionVAE(VAEConfig())
        den = Denoiser(DenoiserConfig(width=32, heads=2, ff_dim=64, layers=3, text_dim=384))
        return SaladPipeline(vae, den, load_text_encoder("minilm"), np.load(sample_dir / "Mean.npy"),
                             np.load(sample_dir / "Std.npy"))
    return make


@pytest.fixture(scope="module")
def pipe(make_tiny_pipeline, request):
    """The test module's own tiny pipeline (:func:`make_tiny_pipeline`), seeded by the module's
    ``PIPE_SEED`` (0 without one): one per module, so what a module's tests set on it stays there."""
    return make_tiny_pipeline(seed=getattr(request.module, "PIPE_SEED", 0))


@pytest.fixture(scope="session")
def tiny_procedural_corpus(tmp_path_factory):
    """The "tiny" procedural corpus (seed 0), built once per test session (a few seconds)."""
    from salad_core.data.procedural import build_corpus

    root = tmp_path_factory.mktemp("tiny_corpus_seed0")
    build_corpus(root, size="tiny", seed=0, progress=False, overwrite=True)
    return root


@pytest.fixture(scope="session")
def tiny_random_evaluator(tiny_procedural_corpus):
    """A random (untrained) tiny T2M evaluator over the tiny corpus's vocabulary and statistics."""
    from _doubles import make_tiny_evaluator

    return make_tiny_evaluator(tiny_procedural_corpus, dim_word=8, dim_text_hidden=16, dim_coemb=32,
                               dim_movement_enc_hidden=16, dim_movement_latent=16, dim_motion_hidden=32)


@pytest.fixture
def recorder(tmp_path) -> tuple[Path, Path]:
    """``(fake, log)``: a stand-in python that records its arguments (one line per call) and succeeds
    (:func:`_doubles.recording_python`), for the resumable shell scripts' tests."""
    from _doubles import recording_python

    return recording_python(tmp_path)


# ----------------------------------------------------------------------------------------------- test tiers
#: The slow tier (``pytest -m slow``); the fast tier is ``pytest -m "not slow"`` (docs/testing.md). Whole modules:
#: every notebook run, the browser, several processes, trainers run to convergence. Single tests: the slowest of
#: ``pytest --durations`` on this project's 2-core machine (each 4-20 s: real training runs, shipped-weight
#: measurements, second processes, byte-for-byte corpus builds).
SLOW_MODULES = frozenset({"test_notebooks", "test_browser", "test_distributed", "test_train_evaluator",
                          "test_keymotion_export"})
SLOW_TESTS = frozenset({
    "test_inversion.py::test_trained_inversion_is_faithful",
    "test_robustness.py::test_same_seed_gives_identical_files_in_two_separate_processes",
    "test_train.py::test_vae_then_denoiser_on_the_procedural_corpus",
    "test_procedural.py::test_build_is_deterministic_byte_for_byte",
    "test_keymotion_train.py::test_cli_trains_three_stages_then_resumes_exactly",
    "test_keymotion_models.py::test_kf_vae_overfits_keyframes_and_indices",
    "test_keymotion_models.py::test_pst_learns_epsilon_on_a_fixed_latent",
    "test_keymotion_models.py::test_train_keymotion_end_to_end_and_resume",
    "test_guidance_sweep.py::test_cli_sweep_on_the_shipped_weights",
    "test_bench_parallel_jobs.py::test_measure_sums_the_processes",
    "test_vae.py::test_overfit_one_real_clip",
    "test_reconstruction.py::test_real_vae_round_trip_is_deterministic_and_sampling_differs",
    "test_editing.py::test_trained_attention_is_localised_on_the_annotated_parts_and_frames",
})


def pytest_collection_modifyitems(config, items):
    """Mark the slow tier (:data:`SLOW_MODULES`, :data:`SLOW_TESTS`) for ``-m "not slow"``."""
    for item in items:
        path = getattr(item, "path", None)
        if path is None:
            continue
        name = getattr(item, "originalname", item.name)
        if path.stem in SLOW_MODULES or f"{path.name}::{name}" in SLOW_TESTS:
            item.add_marker(pytest.mark.slow)
