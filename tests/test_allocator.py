"""salad_core.allocator: after tuning, a freed large block is reused without new page faults."""
from __future__ import annotations

import json
import platform
import subprocess
import sys

import pytest

from salad_core import allocator

pytestmark = pytest.mark.skipif(platform.system() != "Linux" or platform.libc_ver()[0] != "glibc",
                                reason="mallopt tuning is glibc only")

_PROBE = r"""
import json, resource, sys
import torch
from salad_core.allocator import tune_allocator, allocator_tuned
tuned = tune_allocator() if sys.argv[1] == "tune" else False
a = torch.ones(2**20, 12)                                # 48 MiB
def step():                                              # a forward's pattern: large temporaries, above
    h = torch.nn.functional.gelu(a @ torch.ones(12, 12)) # glibc's largest mmap threshold (32 MiB):
    return (h * 2 + 1).sum()                             # 4 new tensors of 48 MiB
for _ in range(3):
    step()                                               # warm-up: the heap grows to its peak
before = resource.getrusage(resource.RUSAGE_SELF).ru_minflt
for _ in range(5):
    step()
print(json.dumps({"tuned": tuned, "flag": allocator_tuned(),
                  "faults": resource.getrusage(resource.RUSAGE_SELF).ru_minflt - before}))
"""


def _run(mode: str) -> dict:
    out = subprocess.run([sys.executable, "-c", _PROBE, mode], check=True, capture_output=True, text=True)
    return json.loads(out.stdout.strip().splitlines()[-1])


def test_tuned_allocator_reuses_freed_large_blocks():
    default, tuned = _run("system"), _run("tune")
    assert default["tuned"] is False and default["flag"] is False
    assert tuned["tuned"] is True and tuned["flag"] is True
    pages = 5 * 4 * 48 * 2**20 // 4096                  # 5 steps x 4 temporaries of 48 MiB
    assert default["faults"] > pages // 2         # glibc default: mmap again, every page faulted in
    assert tuned["faults"] < pages // 4           # tuned: freed heap blocks are reused (at most
                                                  # one temporary faulted in again, heap order)


def test_environment_switch(monkeypatch):
    monkeypatch.setenv(allocator.ENV_VAR, "system")
    assert allocator.tune_from_environment() is False
    monkeypatch.setenv(allocator.ENV_VAR, "jemalloc")
    with pytest.raises(ValueError, match="SALAD_ALLOCATOR must be 'tuned' or 'system'"):
        allocator.tune_from_environment()
