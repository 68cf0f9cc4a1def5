"""DDP: two ``torchrun`` processes (gloo, CPU) on the two halves of each batch train exactly like
one process on the whole batch.

The real command line runs under ``python -m torch.distributed.run --standalone`` (which picks a
free localhost port itself), with the real tiny VAE, and is compared with an in-process run.
"""
from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest
import torch

from salad_core.io import load_tensors
from salad_core.cli.train import main
from salad_core.train.state import load_train_state

sys.path.insert(0, str(Path(__file__).parent))
from _doubles import make_fake_corpus  # noqa: E402

MODEL = {"latent_dim": 8, "n_extra_layers": 0, "dropout": 0.0}  # no dropout: its masks are per process
# Gradients of the two set-ups agree to float rounding (Adam moments within ~1.3e-8 here), but
# Adam's update lr * g / (|g| + eps) turns a rounding difference in a gradient entry near eps into
# a weight difference up to lr * dg / (4 eps): 4.3e-6 measured with the default eps 1e-8, 7.7e-7
# with 1e-6, 2.5e-7 with 1e-5. The test uses 1e-5 so that the 1e-6 tolerance has a margin.
TRAIN = {"max_steps": 2, "warmup_steps": 0, "lr": 1e-2, "milestones": [], "val_every": 0, "ckpt_every": 0,
         "log_every": 1, "seed": 3, "num_threads": 1, "adam_eps": 1e-5}


def _config(tmp_path: Path, batch_size: int) -> Path:
    path = tmp_path / f"conf{batch_size}.json"
    path.write_text(json.dumps({"model": MODEL, "train": {**TRAIN, "batch_size": batch_size}}))
    return path


def _max_diff(a: dict[str, torch.Tensor], b: dict[str, torch.Tensor]) -> float:
    assert sorted(a) == sorted(b)
    return max(float((a[k].double() - b[k].double()).abs().max()) for k in a if a[k].is_floating_point())


def test_two_processes_on_halves_equal_one_process_on_the_whole_batch(tmp_path):
    data = make_fake_corpus(tmp_path / "data")
    one, two, half = tmp_path / "one", tmp_path / "two", tmp_path / "half"
    assert main(["vae", "--data", str(data), "--out", str(one), "--config", str(_config(tmp_path, 8)), "--no-progress"]) == 0
    assert main(["vae", "--data", str(data), "--out", str(half), "--config", str(_config(tmp_path, 4)), "--no-progress"]) == 0

    env = {k: v for k, v in os.environ.items() if k not in ("RANK", "WORLD_SIZE", "LOCAL_RANK", "MASTER_PORT")}
    env.update(OMP_NUM_THREADS="1", GLOO_SOCKET_IFNAME="lo")
    cmd = [sys.executable, "-m", "torch.distributed.run", "--standalone", "--nproc-per-node=2",
           "-m", "salad_core.train", "vae", "--data", str(data), "--out", str(two),
           "--config", str(_config(tmp_path, 8)), "--no-progress"]
    proc = subprocess.run(cmd, env=env, capture_output=True, text=True, timeout=240)
    assert proc.returncode == 0, proc.stderr[-4000:]

    st_one, st_two, st_half = load_train_state(one), load_train_state(two), load_train_state(half)
    assert st_two.step == 2 and len(st_two.rng) == 2  # both ranks' RNG states were gathered
    w_one, w_two = load_tensors(one / "latest.safetensors"), load_tensors(two / "latest.safetensors")
    w_half = load_tensors(half / "latest.safetensors")
    assert _max_diff(w_one, st_one.model_state) == 0.0  # the train state holds the latest weights
    # same updated weights and the same Adam moments (which carry the gradients themselves)
    assert _max_diff(w_one, w_two) < 1e-6
    assert _max_diff(st_one.optim_tensors, st_two.optim_tensors) < 1e-6
    # the comparison can fail: half the batch in one process gives clearly different gradients
    assert _max_diff(st_one.optim_tensors, st_half.optim_tensors) > 1e-4
    assert _max_diff(w_one, w_half) > 1e-4

    # only rank 0 wrote the log; its losses are the all-reduced means, equal to the single process's
    rows_two = [json.loads(l) for l in (two / "log.jsonl").read_text().splitlines()]
    rows_one = [json.loads(l) for l in (one / "log.jsonl").read_text().splitlines()]
    assert [r["step"] for r in rows_two] == [1, 2]
    for a, b in zip(rows_one, rows_two):
        assert abs(a["loss"] - b["loss"]) < 1e-6


def _tiny_bert(folder: Path) -> Path:
    """A randomly initialised 1-layer BERT with MiniLM's tokenizer: a fast stand-in text encoder."""
    from transformers import AutoTokenizer, BertConfig, BertModel

    from salad_core.text import minilm_default_path

    tok = AutoTokenizer.from_pretrained(str(minilm_default_path()), local_files_only=True)
    tok.save_pretrained(folder)
    torch.manual_seed(0)
    BertModel(BertConfig(vocab_size=tok.vocab_size, hidden_size=16, num_hidden_layers=1, num_attention_heads=2,
                         intermediate_size=32, max_position_embeddings=64)).save_pretrained(folder)
    return folder


@pytest.mark.slow
def test_denoiser_two_processes_match_one_process(tmp_path):
    # variable-length batches, caption dropping and the timestep/noise draws must all line up
    data = make_fake_corpus(tmp_path / "data")
    bert = _tiny_bert(tmp_path / "bert")
    vae_conf = tmp_path / "vae.json"
    vae_conf.write_text(json.dumps({"model": MODEL, "train": {"max_steps": 0, "batch_size": 8, "num_threads": 1}}))
    assert main(["vae", "--data", str(data), "--out", str(tmp_path / "vae"), "--config", str(vae_conf), "--no-progress"]) == 0
    conf = tmp_path / "den.json"
    conf.write_text(json.dumps({
        "model": {"latent_dim": 8, "width": 16, "heads": 2, "ff_dim": 32, "layers": 3, "text_dim": 16, "dropout": 0.0},
        "train": {**TRAIN, "batch_size": 4, "max_length": 72, "cond_drop_prob": 0.5, "val_every": 2},
        "text_encoder": str(bert)}))
    args = ["denoiser", "--data", str(data), "--vae", str(tmp_path / "vae"), "--config", str(conf), "--no-progress"]
    assert main([*args, "--out", str(tmp_path / "one")]) == 0
    env = {k: v for k, v in os.environ.items() if k not in ("RANK", "WORLD_SIZE", "LOCAL_RANK", "MASTER_PORT")}
    env.update(OMP_NUM_THREADS="1", GLOO_SOCKET_IFNAME="lo")
    proc = subprocess.run([sys.executable, "-m", "torch.distributed.run", "--standalone", "--nproc-per-node=2",
                           "-m", "salad_core.train", *args, "--out", str(tmp_path / "two")],
                          env=env, capture_output=True, text=True, timeout=240)
    assert proc.returncode == 0, proc.stderr[-4000:]
    one, two = load_train_state(tmp_path / "one"), load_train_state(tmp_path / "two")
    assert _max_diff(one.model_state, two.model_state) < 1e-6
    assert _max_diff(one.optim_tensors, two.optim_tensors) < 1e-6
    rows_one = [json.loads(l) for l in (tmp_path / "one" / "log.jsonl").read_text().splitlines()]
    rows_two = [json.loads(l) for l in (tmp_path / "two" / "log.jsonl").read_text().splitlines()]
    assert [sorted(r) for r in rows_one] == [sorted(r) for r in rows_two]
    for a, b in zip(rows_one, rows_two):
        key = "loss" if "loss" in a else "val_loss"
        assert abs(a[key] - b[key]) < 1e-6
    assert one.best_step == two.best_step == 2
