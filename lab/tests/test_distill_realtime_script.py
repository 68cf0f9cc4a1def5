"""lab/scripts/campaign/distill_realtime_0.4.sh and lab/scripts/salad/distill_realtime.py's control flow: the campaign
runs the distillation (batch 16, resumable), the export and the timing on the run folder; a corpus and a trained
teacher are required; an interrupted distillation exits 130 and exports nothing (the trainer is tested in
tests/test_consistency_distillation.py)."""
from __future__ import annotations

from types import SimpleNamespace

from _doubles import run_stage_script

from _lab import load_script, script_path

SCRIPT = script_path("distill_realtime_0.4.sh")


def teacher_folder(tmp_path):
    teacher = tmp_path / "teacher"
    teacher.mkdir()
    (teacher / "pipeline.json").write_text("{}")
    return teacher


def test_campaign_distils_exports_and_times_the_student(tmp_path, recorder):
    fake, log = recorder
    teacher, out = teacher_folder(tmp_path), tmp_path / "rt"
    out.mkdir()
    res = run_stage_script(SCRIPT, out, python=str(fake), CORPUS="/corpus28", TEACHER=str(teacher), RESUME="1")
    assert res.returncode == 0, res.stderr
    distil, export, timing = log.read_text().splitlines()
    assert distil == (f"lab/scripts/salad/distill_realtime.py --teacher {teacher} --data /corpus28 --out {out}/run "
                      "--steps 8000 --batch-size 16 --ckpt-every 250 --val-every 500 --threads 2 --resume")
    assert export == f"lab/scripts/salad/distill_realtime.py --teacher {teacher} --out {out}/run --export {out}/weights"
    assert timing.endswith(f"--student {out}/weights --time --threads 2")
    assert (out / "timing.jsonl").exists()


def test_campaign_needs_a_corpus_and_a_trained_teacher(tmp_path, recorder):
    fake, log = recorder
    res = run_stage_script(SCRIPT, tmp_path / "rt", python=str(fake), TEACHER=str(teacher_folder(tmp_path)))
    assert res.returncode == 2 and "CORPUS=DIR is required" in res.stderr
    res = run_stage_script(SCRIPT, tmp_path / "rt", python=str(fake), CORPUS="/c", TEACHER=str(tmp_path / "none"))
    assert res.returncode == 2 and "has no pipeline.json" in res.stderr and "train_salad_0.4.sh" in res.stderr
    assert not log.exists() or log.read_text() == ""


def test_an_interrupted_distillation_exits_130_and_exports_nothing(tmp_path, monkeypatch, capsys):
    import salad_core.train.consistency as consistency

    dr = load_script("distill_realtime")
    exported = []
    for interrupted, code in ((True, 130), (False, 0)):
        def fake_train(data, out, config, text_encoder, resume=False, _i=interrupted):
            assert config.batch_size == 16 and config.max_steps == 40 and resume
            return SimpleNamespace(out_dir=out, step=20, last_loss=0.1, best_val=0.02, steps_per_s=0.4, threads=1,
                                   interrupted=_i)

        monkeypatch.setattr(consistency, "train_consistency", fake_train)
        monkeypatch.setattr(dr, "export", lambda args, text_encoder=None: exported.append(args.export))
        rc = dr.main(["--data", "/c", "--out", str(tmp_path / "run"), "--steps", "40", "--batch-size", "16",
                      "--resume", "--export", str(tmp_path / "w")])
        assert rc == code
    assert exported == [str(tmp_path / "w")]                   # only the finished run was exported
    assert "interrupted: continue with --resume" in capsys.readouterr().err
