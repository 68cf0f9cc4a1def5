"""lab/scripts/campaign/evaluate_candidate.sh: the resumable post-training comparison (lab/docs/campaign.md). Its stages are the
``salad eval`` and measuring commands tested elsewhere; here: a finished stage is skipped, a failing one leaves
no marker and stops the script, the commands get the settings, and the assemble stage needs a denoiser."""
from __future__ import annotations

import os
import subprocess
from pathlib import Path

from _doubles import run_stage_script

from _lab import REPO, SHIPPED, STUDY, script_path  # noqa: E402
SCRIPT = script_path("evaluate_candidate.sh")


def _run(out: Path, *stages: str, python: str, **env: str) -> subprocess.CompletedProcess:
    return run_stage_script(SCRIPT, out, *stages, python=python, **{"DATA": "/data/corpus", "WEIGHTS": "/w", **env})


def test_stages_run_once_and_are_skipped_when_done(tmp_path, recorder):
    fake, log = recorder
    out = tmp_path / "out"
    res = _run(out, "physics", "t2m", python=str(fake), EVALUATOR="/ev", PHYSICS_ARGS="--prompts 2 --seeds 1")
    assert res.returncode == 0, res.stderr
    calls = log.read_text().splitlines()
    assert len(calls) == 2
    assert calls[0].startswith("-m salad_core.cli eval --physics --data /data/corpus --threads 2 --evaluator /ev "
                               "--prompts 2 --seeds 1 --weights /w")
    assert "--replications 5 --max-samples 256 --no-mm --weights /w --name candidate" in calls[1]
    assert (out / "physics.done").is_file() and (out / "t2m.done").is_file()
    res = _run(out, "physics", "t2m", python=str(fake))
    assert res.returncode == 0 and res.stdout.count("done before") == 2
    assert len(log.read_text().splitlines()) == 2                     # nothing ran again


def test_a_failing_stage_leaves_no_marker_and_stops(tmp_path):
    out = tmp_path / "out"
    res = _run(out, "physics", "t2m", python="false")
    assert res.returncode != 0
    assert not (out / "physics.done").exists() and not (out / "t2m.log").exists()


def test_settings_are_required(tmp_path, recorder):
    fake, _ = recorder
    env = {**os.environ, "PYTHON": str(fake)}
    env.pop("DATA", None)
    res = subprocess.run(["bash", str(SCRIPT), str(tmp_path / "o"), "physics"], capture_output=True, text=True,
                         env=env, timeout=60)
    assert res.returncode != 0 and "set DATA" in res.stderr
    res = _run(tmp_path / "o2", "assemble", python=str(fake), WEIGHTS=str(tmp_path / "missing"))
    assert res.returncode != 0 and "DENOISER" in res.stderr


def test_assemble_takes_the_denoisers_own_vae_unless_one_is_given(tmp_path, recorder):
    """Without VAE the assembler is not handed any (it takes the VAE the denoiser run recorded); with VAE it gets
    that one (and refuses it if the denoiser did not train on it: tests/test_train.py)."""
    fake, log = recorder
    res = _run(tmp_path / "a", "assemble", python=str(fake), WEIGHTS=str(tmp_path / "wa"), DENOISER="/runs/den")
    assert res.returncode == 0, res.stderr
    assert log.read_text().splitlines()[-1] == f"scripts/assemble_weights.py --denoiser /runs/den --out {tmp_path / 'wa'}"
    res = _run(tmp_path / "b", "assemble", python=str(fake), WEIGHTS=str(tmp_path / "wb"), DENOISER="/runs/den",
               VAE="/runs/vae")
    assert res.returncode == 0, res.stderr
    assert log.read_text().splitlines()[-1] == (f"scripts/assemble_weights.py --vae /runs/vae --denoiser /runs/den "
                                                f"--out {tmp_path / 'wb'}")
