"""lab/scripts/ablations/ablation_decoder_noise.py: the shipped ablation VAEs scored with a VAE stage's protocol under latent noise."""
from __future__ import annotations

import importlib.util
import json
from pathlib import Path

import pytest

from _lab import REPO, SHIPPED, STUDY, script_path  # noqa: E402
pytestmark = pytest.mark.usefixtures("single_thread")


def _script():
    spec = importlib.util.spec_from_file_location("ablation_decoder_noise", script_path("ablation_decoder_noise.py"))
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def _stage(tmp_path: Path, kind: str = "vae") -> Path:
    doc = {"stage": "vaes@6", "kind": kind, "steps": 6,
           "settings": {"split": "test", "batch_size": 32, "max_samples": 32, "seed": 0, "replications": 5}}
    path = tmp_path / "vaes@6.json"
    path.write_text(json.dumps(doc))
    return path


def test_decoder_noise_records_each_vae_at_each_noise_and_pairs_them(tmp_path, tiny_procedural_corpus):
    out = tmp_path / "noise.json"
    assert _script().main(["--data", str(tiny_procedural_corpus), "--stage-eval", str(_stage(tmp_path)),
                           "--variants", "st_long", "pose_long", "--noise", "0", "1.5", "--replications", "2",
                           "--out", str(out)]) == 0
    record = json.loads(out.read_text())
    assert record["stage"] == "vaes@6" and record["settings"]["replications"] == 2 and record["noise"] == [0.0, 1.5]
    for name in ("st_long", "pose_long"):
        row = record["rows"][name]
        assert row["spread_mean"] > 0 and set(row["values"]) == {"0.0", "1.5"}
        assert all(len(v) == 2 for v in row["values"]["1.5"].values())
        # noise of 1.5 spreads moves every pose: MPJPE grows in every replication
        assert min(row["values"]["1.5"]["MPJPE"]) > max(row["values"]["0.0"]["MPJPE"])
    assert set(record["paired"]) == {f"st_long vs pose_long, k {k}, {m}" for k in (0.0, 1.5) for m in ("FID", "MPJPE")}
    assert record["command"].startswith("python lab/scripts/ablations/ablation_decoder_noise.py --data")


def test_decoder_noise_refuses_a_denoiser_stage_and_negative_noise(tmp_path, tiny_procedural_corpus):
    with pytest.raises(SystemExit, match="give a VAE stage"):
        _script().main(["--data", str(tiny_procedural_corpus), "--stage-eval", str(_stage(tmp_path, "denoiser")),
                        "--variants", "st_long", "--noise", "0", "--out", str(tmp_path / "x.json")])
    with pytest.raises(SystemExit):
        _script().main(["--data", str(tiny_procedural_corpus), "--stage-eval", str(_stage(tmp_path)),
                        "--variants", "st_long", "--noise", "-1", "--out", str(tmp_path / "x.json")])
