"""salad_core.keymotion.export: a training root -> a pipeline folder with its run records (runs.json) and the
chosen default guidance; the same motions as the root (fp16 storage aside); a half-trained root is refused."""
from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest
import torch

from salad_core.io import load_tensors
from salad_core.keymotion.export import export_pipeline, export_with_component, run_record, stage_records
from salad_core.keymotion.pipeline import KeyMotionPipeline
from salad_core.keymotion.train import STAGES
from salad_core.sampling import Guidance, parse_guidance_setting
from salad_core.cli.train import main as train_main

from _doubles import HashTextEncoder
from test_keymotion_train import TINY_DOC

pytestmark = pytest.mark.usefixtures("single_thread")


@pytest.fixture(scope="module")
def trained_root(tmp_path_factory) -> Path:
    """A tiny KeyMotion training root: 3 steps per stage on the tiny corpus, hashing text encoder."""
    from salad_core.data.procedural import build_corpus

    mp = pytest.MonkeyPatch()
    mp.setattr("salad_core.text.load_text_encoder", lambda name, device="cpu": HashTextEncoder())
    tmp = tmp_path_factory.mktemp("km_export")
    corpus = tmp / "corpus"
    build_corpus(corpus, size="tiny", seed=0, progress=False)
    cfg = tmp / "km.json"
    cfg.write_text(json.dumps(TINY_DOC))
    root = tmp / "run"
    assert train_main(["keymotion", "--data", str(corpus), "--config", str(cfg), "--out", str(root),
                       "--no-progress"]) == 0
    yield root
    mp.undo()


@pytest.fixture()
def hashing(monkeypatch):
    monkeypatch.setattr("salad_core.text.load_text_encoder", lambda name, device="cpu": HashTextEncoder())


def test_stage_records_say_which_checkpoint_step_and_recipe(trained_root):
    records = stage_records(trained_root)
    assert set(records) == set(STAGES)
    for stage in STAGES:
        rec = records[stage]
        assert rec["checkpoint"] in ("best", "latest") and rec["step"] in (2, 3)   # validation every 2 steps
        assert rec["config"] == json.loads((trained_root / stage / "config.json").read_text())
        assert rec["last_log"]["step"] == 3 and np.isfinite(rec["last_log"]["loss"])
        assert "val_loss" in rec["last_val"]


def test_export_writes_fp16_models_guidance_and_records_and_generates_the_same(trained_root, tmp_path, hashing):
    dest = export_pipeline(trained_root, tmp_path / "w", guidance=Guidance(5.0, rescale=0.5))
    assert {p.name for p in dest.iterdir()} == {f"{s}.{ext}" for s in STAGES for ext in ("safetensors", "json")} \
        | {"keymotion.json", "runs.json"}
    assert json.loads((dest / "runs.json").read_text()) == stage_records(trained_root)
    for stage in STAGES:
        t = load_tensors(dest / f"{stage}.safetensors")
        assert all(v.dtype == torch.float16 for v in t.values() if v.is_floating_point())
    exported = KeyMotionPipeline.from_pretrained(dest)
    assert exported.guidance == Guidance(5.0, rescale=0.5)
    source = KeyMotionPipeline.from_pretrained(trained_root)
    a = source(["a person walks"], lengths=[48], num_steps=3, guidance_scale=2.0, seed=1).features
    b = exported(["a person walks"], lengths=[48], num_steps=3, guidance_scale=2.0, seed=1).features
    assert np.abs(a - b).max() < 0.05 * np.abs(a).max()          # fp16 storage only
    # an exported folder exports again with its records (the shipped folder is one)
    again = export_pipeline(dest, tmp_path / "w2", dtype=None)
    assert (again / "runs.json").read_text() == (dest / "runs.json").read_text()
    assert KeyMotionPipeline.from_pretrained(again).guidance == Guidance(5.0, rescale=0.5)


def test_a_root_missing_a_stage_is_refused_before_anything_is_written(trained_root, tmp_path, hashing):
    half = tmp_path / "half"
    shutil.copytree(trained_root, half)
    shutil.rmtree(half / "mmae")
    with pytest.raises(FileNotFoundError, match=r"mmae does not exist: .* is not a finished KeyMotion training root"):
        export_pipeline(half, tmp_path / "dest")
    assert not (tmp_path / "dest").exists()
    with pytest.raises(TypeError, match="guidance must be a salad_core.sampling.Guidance"):
        export_pipeline(trained_root, tmp_path / "dest2", guidance=5.0)


def test_a_replaced_component_carries_its_run_record_and_keeps_the_others(trained_root, tmp_path, hashing):
    source = export_pipeline(trained_root, tmp_path / "source")
    records = json.loads((source / "runs.json").read_text())
    records["pst"] = {"step": -1, "note": "the record of the model being replaced"}
    (source / "runs.json").write_text(json.dumps(records))
    dest = export_with_component(source, "pst", trained_root / "pst", tmp_path / "dest")
    out = json.loads((dest / "runs.json").read_text())
    assert out["pst"] == run_record(trained_root / "pst") and out["pst"]["step"] in (2, 3)
    assert out["kf_vae"] == records["kf_vae"] and out["mmae"] == records["mmae"]
    stem = out["pst"]["checkpoint"]
    trained = load_tensors(trained_root / "pst" / f"{stem}.safetensors")
    shipped = load_tensors(dest / "pst.safetensors")
    key = next(k for k, v in shipped.items() if v.is_floating_point() and v.numel() > 16)
    assert torch.allclose(shipped[key].float(), trained[key].float().half().float())
    # a source without records: the new component's record alone
    (source / "runs.json").unlink()
    out = json.loads((export_with_component(source, "pst", trained_root / "pst", tmp_path / "d2")
                      / "runs.json").read_text())
    assert set(out) == {"pst"}
    # a run without its config is refused before anything is written
    bare = tmp_path / "bare_run"
    shutil.copytree(trained_root / "pst", bare)
    (bare / "config.json").unlink()
    with pytest.raises(FileNotFoundError, match="config.json is missing"):
        export_with_component(source, "pst", bare, tmp_path / "d3")
    assert not (tmp_path / "d3").exists()


@pytest.mark.parametrize("text, expected", [
    ("7.5", Guidance(7.5)), ("5@0-0.5", Guidance(5.0, interval=(0.0, 0.5))), ("4.5^0.7", Guidance(4.5, rescale=0.7)),
])
def test_guidance_settings_parse(text, expected):
    assert parse_guidance_setting(text) == expected


@pytest.mark.parametrize("text", ["five", "5@0.5", "5@0.6-0.2", "4.5^2", ""])
def test_bad_guidance_settings_name_themselves(text):
    with pytest.raises(ValueError, match="bad guidance setting"):
        parse_guidance_setting(text)
