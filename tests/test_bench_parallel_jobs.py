"""bench/bench_parallel_jobs.py: its workloads train, and its measurement counts the steps of every process."""
from __future__ import annotations

import importlib
import sys
from pathlib import Path

import pytest

SCRIPT = Path(__file__).resolve().parents[1] / "bench" / "bench_parallel_jobs.py"


@pytest.fixture(scope="module")
def bench():
    """The script as a module importable by name: its spawned workers import it again (sys.path goes with them)."""
    sys.path.insert(0, str(SCRIPT.parent))
    try:
        yield importlib.import_module(SCRIPT.stem)
    finally:
        sys.path.remove(str(SCRIPT.parent))
        sys.modules.pop(SCRIPT.stem, None)


@pytest.mark.parametrize("what", ["pst", "denoiser"])
def test_each_workload_is_a_training_step(bench, what):
    """A step runs forward, backward and AdamW: the step changes the weights."""
    import torch

    step, optimizer = bench._make_step(what)
    weights = [p for g in optimizer.param_groups for p in g["params"]]
    before = [w.detach().clone() for w in weights]
    step()
    changed = sum(not torch.equal(a, w) for a, w in zip(before, weights))
    assert changed > len(weights) // 2


def test_unknown_workload_is_named(bench):
    with pytest.raises(ValueError, match="what='gan'"):
        bench._make_step("gan")


def test_measure_sums_the_processes(bench):
    """Two workers side by side report a positive rate each; the sum is what the setting gets."""
    rate = bench.measure("pst", 2, 1, 0.5)
    assert rate > 0.5          # at least one PST step per second in all (about 18 on the project's machine)


def test_settings_are_the_three_choices(bench):
    assert bench.SETTINGS == {"1 process x 1 thread": (1, 1), "1 process x 2 threads": (1, 2),
                              "2 processes x 1 thread": (2, 1)}
