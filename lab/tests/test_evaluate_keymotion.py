"""lab/scripts/keymotion/evaluate_keymotion.sh: the resumable evaluation of a trained KeyMotion run (lab/docs/keymotion_recipe.md).
Its stages are scripts and ``salad eval`` commands tested elsewhere; here: the stages get the weights, data and
settings, a finished stage is skipped, DATA and (for export) RUN are required, and the export stage writes a loadable
fp16 pipeline (run for real). A failing stage leaving no marker is lab/scripts/_stages.sh's, tested with
evaluate_candidate.sh."""
from __future__ import annotations

import subprocess
import sys
from pathlib import Path

from _doubles import run_stage_script

from _lab import REPO, SHIPPED, STUDY, script_path  # noqa: E402
SCRIPT = script_path("evaluate_keymotion.sh")


def _run(out: Path, *stages: str, python: str, **env: str) -> subprocess.CompletedProcess:
    return run_stage_script(SCRIPT, out, *stages, python=python, timeout=300, **{"DATA": "/data/corpus", **env})


def test_measuring_stages_get_the_weights_data_and_settings(tmp_path, recorder):
    fake, log = recorder
    out = tmp_path / "out"
    res = _run(out, "guidance", "physics", "infill", "diversity", "card", python=str(fake), WEIGHTS="/w",
               SETTINGS="7.5 5@0-0.5", THREADS="1")
    assert res.returncode == 0, res.stderr
    calls = log.read_text().splitlines()
    assert calls == [
        f"lab/scripts/keymotion/keymotion_guidance_bench.py --weights /w --settings 7.5 5@0-0.5 --salad --out {out}/guidance.json",
        f"-m salad_core.cli eval --physics --data /data/corpus --threads 1 --keymotion /w --out {out}/physics",
        f"lab/scripts/keymotion/keymotion_infill_ratio.py --weights /w --data /data/corpus --limit 150 --ratios 0.1 0.25 "
        f"--out {out}/infill.json",
        f"lab/scripts/keymotion/keymotion_diversity.py --weights /w --data /data/corpus --out {out}/diversity.json",
        f"lab/scripts/keymotion/keymotion_card_figures.py --data /data/corpus --weights /w --eval --renders {out}/renders "
        f"--out {out}/card.json",
    ]
    res = _run(out, "t2m", "t2m_shipped", python=str(fake), WEIGHTS="/w", THREADS="1", EVALUATOR="/ev")
    assert res.returncode == 0, res.stderr
    assert log.read_text().splitlines()[5:] == [
        f"-m salad_core.cli eval --data /data/corpus --threads 1 --evaluator /ev --replications 5 --max-samples 256 "
        f"--no-mm --keymotion /w --name KeyMotion (candidate) --out {out}/t2m",
        f"-m salad_core.cli eval --data /data/corpus --threads 1 --evaluator /ev --replications 5 --max-samples 256 "
        f"--no-mm --keymotion --name KeyMotion (shipped) --out {out}/t2m_shipped",
    ]
    res = _run(out, python=str(fake), WEIGHTS="/w")                    # all stages: only export is left
    assert res.returncode != 0 and "set RUN" in res.stderr            # ... and it needs the run
    res = _run(out, "guidance", "physics", python=str(fake), WEIGHTS="/w")
    assert res.returncode == 0 and res.stdout.count("done before") == 2
    assert len(log.read_text().splitlines()) == 7                     # nothing ran again


def test_ship_rule_stages_get_the_weights_and_run_the_flight_interval_on_the_ten_seed_benchmark(tmp_path, recorder):
    fake, log = recorder
    out = tmp_path / "out"
    res = _run(out, "physics10", "sides", "stretch", python=str(fake), WEIGHTS="/w", THREADS="1")
    assert res.returncode == 0, res.stderr
    assert log.read_text().splitlines() == [
        f"-m salad_core.cli eval --physics --seeds 10 --no-salad --data /data/corpus --threads 1 --keymotion /w "
        f"--out {out}/physics10",
        f"lab/scripts/keymotion/keymotion_flight_bootstrap.py {out}/physics10/physics.json",
        f"lab/scripts/keymotion/keymotion_side_generation.py --weights /w --seeds 6 --out {out}/sides.json",
        f"lab/scripts/keymotion/keymotion_time_stretch_probe.py --other candidate=/w --salad --json {out}/stretch.json",
    ]
    assert all((out / f"{name}.done").is_file() for name in ("physics10", "sides", "stretch"))


def test_data_and_run_are_required(tmp_path, recorder):
    fake, log = recorder
    res = _run(tmp_path / "o", "physics", python=str(fake), DATA="")
    assert res.returncode != 0 and "set DATA" in res.stderr
    res = _run(tmp_path / "o", "export", "physics", python=str(fake), WEIGHTS="/w")
    assert res.returncode != 0 and "set RUN" in res.stderr and not log.exists()


def test_export_writes_a_loadable_fp16_pipeline(tmp_path):
    # the shipped KeyMotion folder stands in for a training root (from_pretrained reads both)
    import torch

    from salad_core.io import load_tensors
    from salad_core.keymotion.pipeline import KeyMotionPipeline
    from salad_core.sampling import Guidance

    shipped = REPO / "salad_core" / "weights" / "keymotion"
    out = tmp_path / "out"
    res = _run(out, "export", python=sys.executable, RUN=str(shipped), GUIDANCE="5@0-0.5")
    assert res.returncode == 0, res.stderr
    assert "default guidance 5 (interval (0.0, 0.5))" in res.stdout
    assert (out / "weights" / "runs.json").read_text() == (shipped / "runs.json").read_text()   # its records kept
    assert (out / "export.done").is_file() and (out / "weights" / "keymotion.json").is_file()
    for name in ("kf_vae", "pst", "mmae"):
        new = load_tensors(out / "weights" / f"{name}.safetensors")
        old = load_tensors(shipped / f"{name}.safetensors")
        assert new.keys() == old.keys()
        assert all(new[k].dtype == torch.float16 for k in new if new[k].is_floating_point())
        assert all(torch.equal(new[k].float(), old[k].float().half().float()) for k in new)
    pipe = KeyMotionPipeline.from_pretrained(out / "weights")
    assert pipe.default_length == 120 and pipe.guidance == Guidance(5.0, interval=(0.0, 0.5))
    res = _run(tmp_path / "bad", "export", python=sys.executable, RUN=str(shipped), GUIDANCE="five")
    assert res.returncode != 0 and "bad guidance setting 'five'" in res.stdout + res.stderr
