"""salad_core.openmp: the OpenMP wait policy, set by the command line before torch loads (not by
``import salad_core``)."""
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


REPORT = "print(os.environ.get('OMP_WAIT_POLICY'), '|', wait_policy())"


def test_importing_salad_core_leaves_the_process_alone():
    """``import salad_core`` (and its command-line package, train and bench) chooses no policy and loads no torch:
    the command line chooses it, when it runs."""
    code = ("import os, sys, salad_core, salad_core.cli, salad_core.train, salad_core.bench; "
            "from salad_core.openmp import wait_policy; "
            "print(sorted(m for m in ('torch', 'salad_viz', 'matplotlib') if m in sys.modules), '|', end=' '); "
            + REPORT)
    assert _child(code) == "[] | None | not configured"
    assert _child("import os, salad_core, torch; from salad_core.openmp import wait_policy; " + REPORT) \
        == "None | not configured"


def test_the_command_line_sets_the_policy_before_torch_loads():
    # a command that fails fast (no such corpus) still ran the process tuning first, before any torch import
    code = ("import os, sys; from salad_core.cli import main; from salad_core.openmp import wait_policy; "
            "assert main(['-q', 'corpus', 'check', '--out', '/nonexistent/corpus']) == 2; import torch; " + REPORT)
    assert _child(code) == "PASSIVE | passive (set by salad_core before torch loaded)"
    # torch first: too late for libgomp, so salad changes nothing and says why
    late = ("import torch, os; from salad_core.cli import main; from salad_core.openmp import wait_policy; "
            "main(['-q', 'corpus', 'check', '--out', '/nonexistent/corpus']); " + REPORT)
    assert _child(late) == "None | runtime default (torch was imported before the policy was chosen)"


def test_a_python_program_may_choose_the_policy_itself():
    code = ("import os; from salad_core import openmp; openmp.configure(); import torch; "
            "from salad_core.openmp import wait_policy; " + REPORT)
    assert _child(code) == "PASSIVE | passive (set by salad_core before torch loaded)"


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
    # the interpreter's own command line as `python -m salad_core.train vae` leaves it; its __main__ tunes the
    # process (salad_core.cli.tune_process) before it imports the trainers
    code = ("import sys; sys.orig_argv = [sys.executable, '-m', 'salad_core.train', 'vae']; "
            "import os; from salad_core.cli import tune_process; tune_process(); import torch; "
            "from salad_core.openmp import wait_policy; " + REPORT)
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, check=True)
    assert out.stdout.strip() == ("PASSIVE | passive (auto: a training run; set by salad_core before torch "
                                  "loaded)")
