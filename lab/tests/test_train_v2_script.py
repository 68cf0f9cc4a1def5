"""lab/scripts/campaign/train_v2.sh: the training campaign's recipe (lab/docs/campaign.md). Its commands are trainers tested
elsewhere; here, with a stand-in python that records its arguments: each stage runs the trainer with the run
folder's data and outputs, RESUME=1 adds ``--resume``, DEN_DATA redirects the denoiser-side stages, and the
optional stages (vae_decoder, evaluator) run only when named."""
from __future__ import annotations

from pathlib import Path

from _doubles import run_stage_script

from _lab import REPO, SHIPPED, STUDY, script_path  # noqa: E402
SCRIPT = script_path("train_v2.sh")


def test_each_stage_runs_its_trainer_on_the_run_folder(tmp_path, recorder):
    fake, log = recorder
    work = tmp_path / "run"
    res = run_stage_script(SCRIPT, work, "vae", "denoiser", "evaluator", "keymotion", python=str(fake))
    assert res.returncode == 0, res.stderr
    calls = log.read_text().splitlines()
    assert calls == [
        f"-m salad_core.train vae --data {work}/corpus --general {work}/general --out {work}/vae "
        "--config configs/general-vae.json --no-progress",
        f"-m salad_core.train denoiser --data {work}/corpus --out {work}/denoiser --vae {work}/vae "
        "--config configs/salad-0.3/denoiser.json --no-progress",
        f"-m salad_core.eval.train_evaluator --data {work}/corpus --out {work}/evaluator --steps 4000 "
        "--movement-steps 1000 --lr 0.001 --word-vectors contextual --seed 1234 --val-every 250 --threads 1 "
        f"--report-replications 5 --no-progress --export {work}/evaluator_export",
        f"-m salad_core.train keymotion --data {work}/corpus --out {work}/keymotion "
        "--config configs/keymotion-0.2.json --no-progress",
    ]


def test_resume_and_den_data_reach_the_denoiser_side_stages(tmp_path, recorder):
    fake, log = recorder
    work = tmp_path / "run"
    res = run_stage_script(SCRIPT, work, "evaluator", "keymotion", python=str(fake), RESUME="1",
                           DEN_DATA="/corpus27")
    assert res.returncode == 0, res.stderr
    evaluator, keymotion = log.read_text().splitlines()      # the given corpus is not built again
    assert "--data /corpus27 " in evaluator and "--steps 4000 " in evaluator and "--resume" in evaluator
    assert "--data /corpus27 " in keymotion and keymotion.endswith("--resume")


def test_optional_stages_are_not_in_the_default_run(tmp_path, recorder):
    fake, log = recorder
    work = tmp_path / "run"
    for sub in ("corpus/corpus.json", "general/general.json"):      # data already built: the data stage skips it
        (work / sub).parent.mkdir(parents=True)
        (work / sub).write_text("{}")
    res = run_stage_script(SCRIPT, work, python=str(fake))
    assert res.returncode == 0, res.stderr
    stages = [line.split()[2] for line in log.read_text().splitlines()]
    assert stages == ["vae", "denoiser", "keymotion"]                 # no vae_decoder, no evaluator
