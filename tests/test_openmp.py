"""salad_core.openmp: the OpenMP wait policy set before torch loads."""
from __future__ import annotations

import os
import subprocess
import sys

import pytest

from salad_core import openmp


def test_auto_goes_passive_only_on_a_busy_machine():
    env: dict[str, str] = {}
    assert openmp.configure(env, load=1.6, cores=2) == "passive"          # 1.6 >= 0.75 x 2
    assert env["OMP_WAIT_POLICY"] == "PASSIVE"
    quiet: dict[str, str] = {}
    assert openmp.configure(quiet, load=0.4, cores=2) == "runtime default"
    assert "OMP_WAIT_POLICY" not in quiet
    forced = {openmp.ENV_VAR: "passive"}
    assert openmp.configure(forced, load=0.0, cores=2) == "passive"


def test_the_users_variables_and_keep_win():
    env = {"GOMP_SPINCOUNT": "1000"}
    assert openmp.configure(env).startswith("user: GOMP_SPINCOUNT=1000")
    assert "OMP_WAIT_POLICY" not in env
    env = {"OMP_WAIT_POLICY": "ACTIVE"}
    assert openmp.configure(env) == "user: OMP_WAIT_POLICY=ACTIVE" and env["OMP_WAIT_POLICY"] == "ACTIVE"
    env = {openmp.ENV_VAR: "keep"}
    assert openmp.configure(env) == "runtime default" and "OMP_WAIT_POLICY" not in env
    env = {openmp.ENV_VAR: "Active"}
    assert openmp.configure(env) == "active" and env["OMP_WAIT_POLICY"] == "ACTIVE"


def test_bad_choice_names_the_variable():
    with pytest.raises(ValueError, match=openmp.ENV_VAR):
        openmp.configure({openmp.ENV_VAR: "spin"})


def _child(code: str, **extra: str) -> str:
    extra.setdefault(openmp.ENV_VAR, "passive")          # independent of how busy the test machine is
    env = {k: v for k, v in os.environ.items() if k not in ("OMP_WAIT_POLICY", "GOMP_SPINCOUNT", openmp.ENV_VAR)}
    env.update(extra)
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, check=True)
    return out.stdout.strip()


def test_importing_salad_before_torch_sets_the_policy_for_the_process():
    code = ("import os, salad_core, torch; from salad_core.openmp import wait_policy; "
            "print(os.environ.get('OMP_WAIT_POLICY'), '|', wait_policy())")
    assert _child(code) == "PASSIVE | passive (set by salad_core before torch loaded)"
    # torch first: too late for libgomp, so salad changes nothing and says why
    late = ("import torch, os, salad_core; from salad_core.openmp import wait_policy; "
            "print(os.environ.get('OMP_WAIT_POLICY'), '|', wait_policy())")
    assert _child(late) == "None | runtime default (torch was imported before salad_core)"


def test_auto_is_passive_for_a_training_command_even_on_a_quiet_machine():
    for argv in (["python", "-m", "salad_core.train", "vae"], ["python", "-msalad_core.train"],
                 ["/venv/bin/torchrun", "--nproc-per-node", "2", "-m", "salad_core.train", "denoiser"],
                 ["/venv/bin/salad", "train", "vae", "--data", "d"]):
        env: dict[str, str] = {}
        assert openmp.configure(env, load=0.0, cores=2, argv=argv) == "passive", argv
        assert env["OMP_WAIT_POLICY"] == "PASSIVE"
    for argv in (["python", "-m", "salad_core.cli", "sample"], ["/venv/bin/salad", "sample", "train"],
                 ["python", "train.py"]):
        quiet: dict[str, str] = {}
        assert openmp.configure(quiet, load=0.0, cores=2, argv=argv) == "runtime default", argv
    # the user's explicit choice still wins over the training rule
    env = {openmp.ENV_VAR: "active"}
    assert openmp.configure(env, load=0.0, cores=2, argv=["python", "-m", "salad_core.train"]) == "active"


def test_a_training_process_reports_the_training_rule():
    env = {k: v for k, v in os.environ.items() if k not in ("OMP_WAIT_POLICY", "GOMP_SPINCOUNT", openmp.ENV_VAR)}
    # the interpreter's own command line as `python -m salad_core.train vae` would leave it, before the import
    code = ("import sys; sys.orig_argv = [sys.executable, '-m', 'salad_core.train', 'vae']; "
            "import os, salad_core, torch; from salad_core.openmp import wait_policy; "
            "print(os.environ.get('OMP_WAIT_POLICY'), '|', wait_policy())")
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, check=True)
    assert out.stdout.strip() == ("PASSIVE | passive (auto: a training run; set by salad_core before torch "
                                  "loaded)")
