"""The shell recipes of issue 24's denoiser probes call the probe scripts with the right arguments, in order.

The Python steps they drive (config, training, scoring, continuation) are tested in test_ablation_probes.py; here a
stand-in interpreter records each call's arguments one by one, so the recipe's wiring (and its word splitting) is
checked without training anything."""
from __future__ import annotations

import json
import os
import stat
import subprocess
from pathlib import Path

import pytest

from _lab import REPO, SHIPPED, STUDY, script_path  # noqa: E402

FAKE_PYTHON = """#!/usr/bin/env bash
# records its arguments (one per field); answers the recipe's two inline questions (a run's VAE, a run's step)
if [ "$1" = "-c" ]; then
    case "$2" in
        *'"task"'*) echo "VAE_OF_$(basename "$(dirname "$3")")" ;;
        *'sys.argv[2]'*) echo "STUDY_VAE_OF_$4" ;;   # a restored study: study_vaes.json
        *) exit 1 ;;                       # no latest.json yet: the recipe reads step 0
    esac
    exit 0
fi
printf '%s\\037' "$@" >> "$CALLS"
printf '\\n' >> "$CALLS"
"""
SIZE_SETS = ["--set", "model.width=128", "model.ff_dim=512", "model.layers=5"]
DECAY_SETS = ["--set", "train.max_steps=10000", "train.milestones=[7500,8500]"]


@pytest.fixture()
def fake_python(tmp_path):
    exe = tmp_path / "python"
    exe.write_text(FAKE_PYTHON)
    exe.chmod(exe.stat().st_mode | stat.S_IEXEC)
    study = tmp_path / "study"
    study.mkdir()
    (study / "probes.json").write_text(json.dumps({"no_st_w128": {}}))   # already scored: not scored again
    for v in ("no_st", "full", "x0"):      # the study's work folder on the machine that trained it
        (tmp_path / "work" / f"den_{v}").mkdir(parents=True)
        (tmp_path / "work" / f"den_{v}" / "config.json").write_text("{}")
    (tmp_path / "work" / "configs").mkdir()
    env = {**os.environ, "PYTHON": str(exe), "CALLS": str(tmp_path / "calls.txt"), "STUDY": str(study),
           "STUDY_WORK": str(tmp_path / "work"), "DATA": str(tmp_path / "corpus")}
    return tmp_path, env


def _calls(tmp_path: Path) -> list[list[str]]:
    """Each call's arguments, as the interpreter received them."""
    return [line.split("\037")[:-1] for line in (tmp_path / "calls.txt").read_text().splitlines()]


def _run_recipe(fake, script: str, *args: str) -> tuple[Path, Path, list[list[str]]]:
    """Run ``scripts/<script>`` with the recording interpreter: ``(tmp_path, OUT, calls)``."""
    tmp_path, env = fake
    out = tmp_path / "out"
    subprocess.run(["bash", str(script_path(script)), str(out), *args], env=env, check=True, cwd=tmp_path)
    return tmp_path, out, _calls(tmp_path)


def _train(tmp_path: Path, run: Path, vae: str) -> list[str]:
    return ["-m", "salad_core.train", "denoiser", "--data", f"{tmp_path}/corpus", "--out", str(run), "--config",
            f"{run}.json", "--vae", vae, "--no-progress", "--resume"]


def test_size_probe_configures_trains_scores_and_continues_each_variant(fake_python):
    tmp_path, out, calls = _run_recipe(fake_python, "probe_denoiser_size.sh", "no_st", "full")
    assert calls[0] == (["lab/scripts/ablations/ablation_denoiser_probe.py", "config", "--study-configs", f"{tmp_path}/work/configs",
                         "--variant", "no_st", "--vae", "VAE_OF_den_no_st"] + SIZE_SETS
                        + ["--out", f"{out}/den_no_st_w128.json"])
    assert calls[1] == _train(tmp_path, out / "den_no_st_w128", "VAE_OF_den_no_st")
    # no_st_w128 is already in the record: only full is scored, with the same change and its own VAE
    assert calls[2][:6] == ["lab/scripts/ablations/ablation_denoiser_probe.py", "config", "--study-configs",
                            f"{tmp_path}/work/configs", "--variant", "full"]
    assert calls[3] == _train(tmp_path, out / "den_full_w128", "VAE_OF_den_full")
    score = calls[4]
    assert score[:14] == ["lab/scripts/ablations/ablation_denoiser_probe.py", "score", "--stage-eval",
                          "salad_core/weights/ablations/evaluations/denoisers@8000.json", "--run", f"{out}/den_full_w128",
                          "--vae", "VAE_OF_den_full", "--name", "full_w128", "--variant", "full", "--vae-label",
                          "the study's own VAE for this row"]
    assert score[14:18] == SIZE_SETS
    assert score[18:20] == ["--label", "full, at the shipped denoiser's size (width 128, 5 layers)"]
    assert calls[5] == (["lab/scripts/ablations/ablation_continuation_probe.py", "prepare", "--study-work", f"{tmp_path}/work",
                         "--variants", f"no_st_w128={out}/den_no_st_w128", f"full_w128={out}/den_full_w128"]
                        + DECAY_SETS + ["--out-dir", f"{out}/decay_w128"])
    assert calls[6] == _train(tmp_path, out / "decay_w128" / "den_no_st_w128", "VAE_OF_den_no_st")
    assert calls[7] == _train(tmp_path, out / "decay_w128" / "den_full_w128", "VAE_OF_den_full")
    assert len(calls) == 8


def test_seed_probe_is_the_same_recipe_with_the_seed(fake_python):
    tmp_path, out, calls = _run_recipe(fake_python, "probe_training_seed.sh", "2026", "full")
    assert calls[0][-4:] == ["--set", "train.seed=2026", "--out", f"{out}/den_full_s2026.json"]
    assert calls[2][8:10] == ["--name", "full_s2026"] and "full, training seed 2026" in calls[2]
    assert calls[3][-6:] == [f"full_s2026={out}/den_full_s2026"] + DECAY_SETS + ["--out-dir", f"{out}/decay_s2026"]


def test_probe_recipe_on_a_restored_study_writes_its_configs_and_reads_its_vaes(fake_python):
    """A new machine: the study's work folder holds only the restored groups (no configs/, no den_<v>/)."""
    tmp_path, env = fake_python
    work = tmp_path / "restored"
    work.mkdir()
    env = {**env, "STUDY_WORK": str(work)}
    out = tmp_path / "out"
    subprocess.run(["bash", str(script_path("probe_denoiser_size.sh")), str(out), "full"], env=env, check=True,
                   cwd=REPO)
    calls = _calls(tmp_path)
    assert calls[0] == ["lab/scripts/ablations/ablation_denoiser_probe.py", "study-configs", "--recipe", "lab/configs/ablations_v2.json",
                        "--work", str(work)]
    assert calls[1][:8] == ["lab/scripts/ablations/ablation_denoiser_probe.py", "config", "--study-configs", f"{work}/configs",
                            "--variant", "full", "--vae", "STUDY_VAE_OF_full"]
    assert calls[2] == _train(tmp_path, out / "den_full_w128", "STUDY_VAE_OF_full")


@pytest.mark.parametrize("args, message", [((), "name at least one study denoiser variant"),
                                           (("full",), "")])
def test_probe_recipe_refuses_a_call_without_variants_or_changes(fake_python, args, message):
    tmp_path, env = fake_python
    sets = "train.seed=1" if not args else "  "
    res = subprocess.run(["bash", str(script_path("probe_denoisers.sh")), str(tmp_path / "out"), "t", "what",
                          sets, *args], env=env, cwd=tmp_path, capture_output=True, text=True)
    assert res.returncode == 2
    assert (message or "give at least one KEY=VALUE change") in res.stderr
    assert not (tmp_path / "calls.txt").exists()


def test_probe_recipe_refuses_a_tag_with_a_dot(fake_python):
    tmp_path, env = fake_python
    res = subprocess.run(["bash", str(script_path("probe_denoisers.sh")), str(tmp_path / "out"), "lr0.5",
                          "what", "train.lr=0.5", "full"], env=env, cwd=tmp_path, capture_output=True, text=True)
    assert res.returncode == 2 and "TAG 'lr0.5'" in res.stderr
