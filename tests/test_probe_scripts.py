"""The shell recipes of issue 24's denoiser probes call the probe scripts with the right arguments, in order.

The Python steps they drive (config, training, scoring, continuation) are tested in test_ablation_probes.py; here a
stand-in interpreter records each call, so the recipe's wiring is checked without training anything."""
from __future__ import annotations

import json
import os
import stat
import subprocess
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]

FAKE_PYTHON = """#!/usr/bin/env bash
# records its arguments; answers the recipe's two inline questions (a run's VAE, a run's step)
if [ "$1" = "-c" ]; then
    case "$2" in
        *'"task"'*) echo "VAE_OF_$(basename "$(dirname "$3")")" ;;
        *) exit 1 ;;                       # no latest.json yet: the recipe reads step 0
    esac
    exit 0
fi
printf '%s\\n' "$*" >> "$CALLS"
"""


@pytest.fixture()
def fake_python(tmp_path):
    exe = tmp_path / "python"
    exe.write_text(FAKE_PYTHON)
    exe.chmod(exe.stat().st_mode | stat.S_IEXEC)
    study = tmp_path / "study"
    study.mkdir()
    (study / "probes.json").write_text(json.dumps({"no_st_w128": {}}))   # already scored: not scored again
    env = {**os.environ, "PYTHON": str(exe), "CALLS": str(tmp_path / "calls.txt"), "STUDY": str(study),
           "STUDY_WORK": str(tmp_path / "work"), "DATA": str(tmp_path / "corpus")}
    return tmp_path, env


def _calls(tmp_path: Path) -> list[str]:
    return (tmp_path / "calls.txt").read_text().splitlines()


def test_size_probe_configures_trains_scores_and_continues_each_variant(fake_python):
    tmp_path, env = fake_python
    out = tmp_path / "out"
    subprocess.run(["bash", str(REPO / "scripts" / "probe_denoiser_size.sh"), str(out), "no_st", "full"], env=env,
                   check=True, cwd=tmp_path)
    calls = _calls(tmp_path)
    sets = "--set model.width=128 model.ff_dim=512 model.layers=5"
    assert calls[0] == (f"scripts/ablation_denoiser_probe.py config --study-configs {tmp_path}/work/configs --variant "
                        f"no_st --vae VAE_OF_den_no_st {sets} --out {out}/den_no_st_w128.json")
    assert calls[1] == (f"-m salad_core.train denoiser --data {tmp_path}/corpus --out {out}/den_no_st_w128 --config "
                        f"{out}/den_no_st_w128.json --vae VAE_OF_den_no_st --no-progress --resume")
    # no_st_w128 is already in the record: only full is scored, with the same change and its own VAE
    assert calls[2].startswith("scripts/ablation_denoiser_probe.py config") and "--variant full" in calls[2]
    assert calls[3].startswith(f"-m salad_core.train denoiser --data {tmp_path}/corpus --out {out}/den_full_w128 ")
    score = calls[4]
    assert score.startswith(f"scripts/ablation_denoiser_probe.py score --stage-eval {tmp_path}/study/evaluations/"
                            f"denoisers@8000.json --run {out}/den_full_w128 --vae VAE_OF_den_full --name full_w128 "
                            f"--variant full")
    assert sets in score and "--label full, at the shipped denoiser's size (width 128, 5 layers)" in score
    assert calls[5] == (f"scripts/ablation_continuation_probe.py prepare --study-work {tmp_path}/work --variants "
                        f"no_st_w128={out}/den_no_st_w128 full_w128={out}/den_full_w128 --set train.max_steps=10000 "
                        f"train.milestones=[7500,8500] --out-dir {out}/decay_w128")
    assert calls[6].startswith(f"-m salad_core.train denoiser --data {tmp_path}/corpus --out "
                               f"{out}/decay_w128/den_no_st_w128 --config {out}/decay_w128/den_no_st_w128.json")
    assert calls[7].startswith(f"-m salad_core.train denoiser --data {tmp_path}/corpus --out "
                               f"{out}/decay_w128/den_full_w128 ")
    assert len(calls) == 8


def test_seed_probe_is_the_same_recipe_with_the_seed(fake_python):
    tmp_path, env = fake_python
    out = tmp_path / "out"
    subprocess.run(["bash", str(REPO / "scripts" / "probe_training_seed.sh"), str(out), "2026", "full"], env=env,
                   check=True, cwd=tmp_path)
    calls = _calls(tmp_path)
    assert calls[0].endswith(f"--set train.seed=2026 --out {out}/den_full_s2026.json")
    assert "--name full_s2026" in calls[2] and "--label full, training seed 2026" in calls[2]
    assert calls[3].endswith(f"--variants full_s2026={out}/den_full_s2026 --set train.max_steps=10000 "
                             f"train.milestones=[7500,8500] --out-dir {out}/decay_s2026")


def test_probe_recipe_refuses_a_call_without_variants(fake_python):
    tmp_path, env = fake_python
    res = subprocess.run(["bash", str(REPO / "scripts" / "probe_denoisers.sh"), str(tmp_path / "out"), "t", "what",
                          "train.seed=1"], env=env, cwd=tmp_path, capture_output=True, text=True)
    assert res.returncode == 2 and "name at least one study denoiser variant" in res.stderr
