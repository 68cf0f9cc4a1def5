"""Trainers: schedule, configs, run-folder layout, best vs latest, exact resume, SIGINT, disk full.

Everything runs on a tiny fake corpus (random smooth features of width 263, two captions per
clip) written to a temporary folder, with tiny models and one CPU thread.
"""
from __future__ import annotations

import copy
import errno
import json
import os
import signal
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest
import torch
from torch import nn

from salad_core.io import CheckpointError, load_model, load_tensors, read_checkpoint
from salad_core.skeleton import get_skeleton
from salad_core.train import (
    DenoiserTrainConfig,
    TrainTask,
    VAETrainConfig,
    fit,
    load_train_config,
    lr_at_step,
    save_train_config,
    train_denoiser,
    train_vae,
)
from salad_core.train.distributed import DistEnv, GlobalBatchRandom
from salad_core.train.state import capture_rng, load_train_state, optimizer_from_flat, optimizer_to_flat, restore_rng
from _doubles import HashTextEncoder, make_fake_corpus

SK = get_skeleton("humanml3d")
# ----------------------------------------------------------------------------- fixtures
@pytest.fixture(scope="module")
def corpus(tmp_path_factory) -> Path:
    return make_fake_corpus(tmp_path_factory.mktemp("corpus"))


def tiny_vae_config(dropout: float = 0.1):
    from salad_core.models.vae import VAEConfig

    return VAEConfig(latent_dim=8, n_extra_layers=0, dropout=dropout)


def vae_train_config(**kw) -> VAETrainConfig:
    base = dict(batch_size=8, max_steps=6, lr=3e-3, warmup_steps=2, milestones=(4,), gamma=0.5, window=64,
                val_every=0, ckpt_every=0, log_every=1, num_threads=1, progress=False, seed=3)
    base.update(kw)
    return VAETrainConfig(**base)


def weights(path: Path) -> dict[str, torch.Tensor]:
    return load_tensors(path)


def assert_same_tensors(a: dict[str, torch.Tensor], b: dict[str, torch.Tensor]) -> None:
    assert sorted(a) == sorted(b)
    for k in a:
        assert torch.equal(a[k], b[k]), f"tensor {k} differs (max abs diff {(a[k].float() - b[k].float()).abs().max()})"


@pytest.fixture(scope="module")
def straight_vae(corpus, tmp_path_factory) -> Path:
    """Reference: 6 steps in one go (26 windows: 3 batches of 8 per epoch, so 2 epochs)."""
    out = tmp_path_factory.mktemp("straight")
    res = train_vae(corpus, out, tiny_vae_config(), vae_train_config())
    assert res.step == 6 and not res.interrupted
    return out


# ------------------------------------------------------------------------ schedule/config
def test_lr_schedule_warmup_then_steps():
    base, warm = 2e-4, 4
    got = [lr_at_step(s, base, warm, (3, 6), 0.1) for s in range(12)]
    want = [base * 1 / 5, base * 2 / 5, base * 3 / 5, base * 4 / 5,        # lr*(it+1)/(warm+1)
            base, base, base,                                               # it - warm < 3
            base * 0.1, base * 0.1, base * 0.1,                             # 3 <= it - warm < 6
            base * 0.01, base * 0.01]
    np.testing.assert_allclose(got, want, rtol=1e-12)
    assert lr_at_step(0, 1.0, 0, (), 0.5) == 1.0
    with pytest.raises(ValueError, match="step=-1"):
        lr_at_step(-1, 1.0, 0, (), 0.5)


def test_config_defaults_are_the_official_recipe_and_round_trip(tmp_path):
    v, d = VAETrainConfig(), DenoiserTrainConfig()
    assert (v.batch_size, v.lr, v.warmup_steps, v.milestones, v.gamma, v.weight_decay, v.window, v.max_epochs) == \
        (256, 2e-4, 2000, (150_000, 250_000), 0.05, 0.0, 64, 50)
    assert (d.batch_size, d.lr, d.warmup_steps, d.milestones, d.gamma, d.weight_decay, d.cond_drop_prob, d.max_length) == \
        (64, 5e-4, 2000, (50_000,), 0.1, 1e-6, 0.1, 196)
    assert v.betas == d.betas == (0.9, 0.99)
    cfg = d.replace(batch_size=12, milestones=(5, 9), grad_clip=1.0)
    save_train_config(tmp_path / "c.json", cfg)
    assert load_train_config(tmp_path / "c.json", DenoiserTrainConfig) == cfg
    assert load_train_config(tmp_path / "c.json", DenoiserTrainConfig, max_steps=7).max_steps == 7
    with pytest.raises(ValueError, match="batch_size=0"):
        VAETrainConfig(batch_size=0)
    with pytest.raises(ValueError, match="cond_drop_prob=1.5"):
        DenoiserTrainConfig(cond_drop_prob=1.5)
    with pytest.raises(ValueError, match="milestones"):
        VAETrainConfig(milestones=(5, 3))
    with pytest.raises(CheckpointError, match="unknown config keys"):
        (tmp_path / "bad.json").write_text(json.dumps({"batch_sise": 3}))
        load_train_config(tmp_path / "bad.json", VAETrainConfig)


# --------------------------------------------------------------------- randomness / state
def test_global_batch_random_gives_each_rank_its_rows_of_the_global_draw():
    full = GlobalBatchRandom(torch.Generator().manual_seed(5), DistEnv()).randn(6, (2, 3))
    for rank in range(2):
        env = DistEnv(rank=rank, world_size=2)
        part = GlobalBatchRandom(torch.Generator().manual_seed(5), env).randn(3, (2, 3))
        assert torch.equal(part, full[rank::2])
    ints = GlobalBatchRandom(torch.Generator().manual_seed(1), DistEnv()).randint(1000, 10)
    assert ints.min() >= 0 and ints.max() < 10 and len(set(ints.tolist())) == 10


def test_optimizer_and_rng_state_round_trip_exactly():
    torch.manual_seed(0)
    model = nn.Linear(4, 3)
    opt = torch.optim.AdamW(model.parameters(), lr=0.1, betas=(0.9, 0.99))
    for _ in range(2):
        opt.zero_grad()
        model(torch.randn(5, 4)).pow(2).sum().backward()
        opt.step()
    tensors, doc = optimizer_to_flat(opt)
    json.dumps(doc)  # the scalar part is JSON
    opt2 = torch.optim.AdamW(model.parameters(), lr=0.5)
    optimizer_from_flat(opt2, tensors, doc)
    a, b = opt.state_dict(), opt2.state_dict()
    assert a["param_groups"][0]["betas"] == b["param_groups"][0]["betas"] and b["param_groups"][0]["lr"] == 0.1
    for i in a["state"]:
        for k in a["state"][i]:
            assert torch.equal(a["state"][i][k], b["state"][i][k])

    import random

    snap = capture_rng()
    draws = (torch.rand(3), np.random.rand(3), random.random())
    restore_rng(snap)
    again = (torch.rand(3), np.random.rand(3), random.random())
    assert torch.equal(draws[0], again[0]) and np.array_equal(draws[1], again[1]) and draws[2] == again[2]


def test_adamw_implementations_give_the_same_update_and_share_their_state():
    from salad_core.train.config import ADAMW_IMPLEMENTATIONS, make_adamw

    torch.manual_seed(0)
    start = nn.Sequential(nn.Linear(6, 5), nn.GELU(), nn.Linear(5, 3))
    x = torch.randn(8, 6)
    models, opts = {}, {}
    for impl in ADAMW_IMPLEMENTATIONS:
        models[impl] = copy.deepcopy(start)
        opts[impl] = make_adamw(list(models[impl].parameters()), DenoiserTrainConfig(adamw=impl), lr=1e-2)
    assert opts["fused"].defaults["fused"] and opts["foreach"].defaults["foreach"]
    assert opts["loop"].defaults["foreach"] is False and not opts["loop"].defaults["fused"]
    for _ in range(5):
        for impl, m in models.items():
            opts[impl].zero_grad()
            m(x).pow(2).mean().backward()
            opts[impl].step()
    for impl in ("fused", "foreach"):
        for a, b in zip(models["loop"].parameters(), models[impl].parameters()):
            torch.testing.assert_close(a, b, atol=1e-6, rtol=1e-5)
    moved = max(float((a - b).abs().max()) for a, b in zip(start.parameters(), models["loop"].parameters()))
    assert moved > 1e-2                                           # the five steps did move the weights
    # a loop optimiser's state continues in a fused one (a run may resume with another implementation)
    resumed = copy.deepcopy(models["loop"])
    fused = make_adamw(list(resumed.parameters()), DenoiserTrainConfig(adamw="fused"), lr=1e-2)
    tensors, doc = optimizer_to_flat(opts["loop"])                    # as the trainer saves and loads it
    optimizer_from_flat(fused, {k: v.clone() for k, v in tensors.items()}, doc)
    assert fused.param_groups[0]["fused"] is True                      # still the fused implementation
    for opt, m in ((opts["loop"], models["loop"]), (fused, resumed)):
        opt.zero_grad()
        m(x).pow(2).mean().backward()
        opt.step()
    for a, b in zip(models["loop"].parameters(), resumed.parameters()):
        torch.testing.assert_close(a, b, atol=1e-6, rtol=1e-5)
    with pytest.raises(ValueError, match="adamw='lamb'"):
        DenoiserTrainConfig(adamw="lamb")


def test_resumable_batch_sampler_skips_used_batches():
    from salad_core.train.common import ResumableBatchSampler

    idx = list(range(10))
    assert list(ResumableBatchSampler(idx, 3, drop_last=True)) == [[0, 1, 2], [3, 4, 5], [6, 7, 8]]
    assert list(ResumableBatchSampler(idx, 3, drop_last=True, start=1)) == [[3, 4, 5], [6, 7, 8]]
    assert list(ResumableBatchSampler(idx, 3, drop_last=False, start=3)) == [[9]]
    for drop in (True, False):
        for start in range(5):
            sampler = ResumableBatchSampler(idx, 3, drop_last=drop, start=start)
            assert len(list(sampler)) == len(sampler)


# ------------------------------------------------------------------ a stand-in scalar task
@dataclass(frozen=True)
class ScalarConfig:
    init: float = 0.2     # initial value of the single weight


class ScalarModel(nn.Module):
    def __init__(self, config: ScalarConfig) -> None:
        super().__init__()
        self.w = nn.Parameter(torch.tensor([config.init]))


class ScalarObjective(nn.Module):
    def __init__(self, model: ScalarModel) -> None:
        super().__init__()
        self.model = model

    def forward(self, c: torch.Tensor) -> dict[str, torch.Tensor]:
        return {"loss": (self.model.w - c).pow(2).mean()}


def scalar_task(train_target: float = 1.0, val_target: float = 0.5) -> TrainTask:
    model = ScalarModel(ScalarConfig())
    return TrainTask(
        model=model, model_type="test_scalar", model_config=ScalarConfig(), objective=ScalarObjective(model),
        train_set=[{"c": train_target}] * 8, val_set=[{"c": val_target}] * 4,
        collate=lambda items: {"c": torch.tensor([it["c"] for it in items])},
        prepare=lambda batch, ctx: {"c": batch["c"]},
    )


def test_best_checkpoint_is_kept_apart_from_latest(tmp_path):
    # training pulls w from 0.2 towards 1.0; validation wants 0.5, so the best step lies mid-run
    seen: dict[int, float] = {}
    task = scalar_task()
    cfg = VAETrainConfig(batch_size=4, max_steps=16, lr=0.05, warmup_steps=0, val_every=1, ckpt_every=5,
                         log_every=1, num_threads=1, progress=False)
    res = fit(task, tmp_path, cfg, on_step=lambda s: seen.__setitem__(s, task.model.w.item()))
    assert 2 <= res.best_step < 16
    best_doc, best = read_checkpoint(tmp_path / "best")
    latest_doc, latest = read_checkpoint(tmp_path / "latest")
    assert best_doc["meta"]["step"] == res.best_step and latest_doc["meta"]["step"] == 16
    assert float(best["w"]) == pytest.approx(seen[res.best_step], abs=0)
    assert float(latest["w"]) == pytest.approx(seen[16], abs=0)
    assert abs(float(best["w"]) - 0.5) < abs(float(latest["w"]) - 0.5)
    val = [json.loads(l) for l in (tmp_path / "log.jsonl").read_text().splitlines() if "val_loss" in l]
    assert len(val) == 16
    assert min(val, key=lambda e: e["val_loss"])["step"] == res.best_step
    assert best_doc["meta"]["val_loss"] == pytest.approx(min(e["val_loss"] for e in val), abs=0)


def test_logged_learning_rate_follows_the_schedule(tmp_path):
    cfg = VAETrainConfig(batch_size=2, max_steps=9, lr=0.01, warmup_steps=3, milestones=(2, 4), gamma=0.5,
                         val_every=0, log_every=1, num_threads=1, progress=False)
    fit(scalar_task(), tmp_path, cfg)
    rows = [json.loads(l) for l in (tmp_path / "log.jsonl").read_text().splitlines()]
    assert [r["step"] for r in rows] == list(range(1, 10))
    for r in rows:  # the lr logged at step s was used for iteration s - 1
        assert r["lr"] == pytest.approx(lr_at_step(r["step"] - 1, 0.01, 3, (2, 4), 0.5), rel=1e-12)
    assert not (tmp_path / "best.safetensors").exists()  # val_every=0: no validation


# ------------------------------------------------------------------------------ VAE runs
def test_vae_run_folder_layout(straight_vae):
    out = straight_vae
    names = sorted(p.name for p in out.iterdir())
    assert names == sorted(["config.json", "latest.json", "latest.safetensors", "log.jsonl", "mean_std.safetensors",
                            "train_state.json", "train_state.safetensors"])  # val_every=0: no best.*
    model, config, meta = load_model(out / "latest")
    assert config == tiny_vae_config() and meta["step"] == 6 and meta["window"] == 64
    state = json.loads((out / "train_state.json").read_text())
    assert state["step"] == 6 and state["world_size"] == 1 and state["optimizer"]["class"] == "AdamW"
    assert state["lr"] == pytest.approx(lr_at_step(5, 3e-3, 2, (4,), 0.5))
    ts = load_train_state(out)
    assert_same_tensors(ts.model_state, dict(model.state_dict()))  # the train state holds the same weights
    assert any(k.endswith(".exp_avg_sq") for k in ts.optim_tensors)
    cfg = json.loads((out / "config.json").read_text())
    assert cfg["model_type"] == "salad_vae" and cfg["train"]["batch_size"] == 8 and cfg["model"]["latent_dim"] == 8
    rows = [json.loads(l) for l in (out / "log.jsonl").read_text().splitlines()]
    assert [r["step"] for r in rows] == [1, 2, 3, 4, 5, 6]
    assert {"loss", "rec", "pos", "vel", "kl", "lr"} <= set(rows[0])
    ms = load_tensors(out / "mean_std.safetensors")
    assert ms["mean"].shape == (SK.feature_dim,)


def test_vae_loss_decreases_on_tiny_overfit(corpus, tmp_path):
    from salad_core.models.vae import VAEConfig

    cfg = vae_train_config(max_steps=30, lr=1e-2, warmup_steps=0, milestones=(), log_every=5)
    res = train_vae(corpus, tmp_path, VAEConfig(latent_dim=16, n_extra_layers=0, dropout=0.0), cfg)
    rows = [json.loads(l) for l in (tmp_path / "log.jsonl").read_text().splitlines()]
    first, last = rows[0]["rec"], rows[-1]["rec"]
    assert last < 0.8 * first, (first, last)
    assert res.last_loss == pytest.approx(rows[-1]["loss"])
    assert res.steps_per_s > 0


def test_vae_resume_is_bit_identical(corpus, straight_vae, tmp_path):
    first = train_vae(corpus, tmp_path, tiny_vae_config(), vae_train_config(max_steps=4))
    st = load_train_state(tmp_path)
    assert first.step == 4 and (st.epoch, st.batch_in_epoch) == (1, 1)  # stopped mid-epoch
    res = train_vae(corpus, tmp_path, tiny_vae_config(), vae_train_config(), resume=True)
    assert res.step == 6 and res.epoch == 2
    assert_same_tensors(weights(tmp_path / "latest.safetensors"), weights(straight_vae / "latest.safetensors"))
    a, b = load_train_state(tmp_path), load_train_state(straight_vae)
    assert_same_tensors(a.optim_tensors, b.optim_tensors)
    assert_same_tensors(a.rng[0].tensors, b.rng[0].tensors)
    rows = [json.loads(l) for l in (tmp_path / "log.jsonl").read_text().splitlines()]
    ref = [json.loads(l) for l in (straight_vae / "log.jsonl").read_text().splitlines()]
    assert [r["step"] for r in rows] == [1, 2, 3, 4, 5, 6]
    assert [r["loss"] for r in rows] == [r["loss"] for r in ref]


def test_sigint_writes_a_consistent_checkpoint_then_resume_matches(corpus, straight_vae, tmp_path):
    def interrupt(step: int) -> None:
        if step == 3:
            os.kill(os.getpid(), signal.SIGINT)

    # step 3 ends epoch 0: the resumed run starts with an exhausted epoch and must move on
    handler = signal.getsignal(signal.SIGINT)
    res = train_vae(corpus, tmp_path, tiny_vae_config(), vae_train_config(), on_step=interrupt)
    assert res.interrupted and res.step == 3
    assert signal.getsignal(signal.SIGINT) is handler  # the caller's handler is back
    ts = load_train_state(tmp_path)
    latest_doc, latest = read_checkpoint(tmp_path / "latest")
    assert ts.step == 3 and ts.extra["reason"] == "interrupt" and latest_doc["meta"]["step"] == 3
    assert_same_tensors(ts.model_state, latest)
    load_model(tmp_path / "latest")  # rebuilds
    res = train_vae(corpus, tmp_path, tiny_vae_config(), vae_train_config(), resume=True)
    assert res.step == 6 and not res.interrupted
    assert_same_tensors(weights(tmp_path / "latest.safetensors"), weights(straight_vae / "latest.safetensors"))


def test_warm_start_continues_from_fp16_weights_with_a_new_warm_up(corpus, straight_vae, tmp_path):
    """A run folder holding only the fp16 weights of a step continues from that step: the epoch position an
    exact resume would have, the learning rate warmed up again, and the train state says so for later resumes."""
    from salad_core.train.warm_start import load_warm_start, rewarm_factor, write_warm_start

    first = tmp_path / "first"
    train_vae(corpus, first, tiny_vae_config(), vae_train_config(max_steps=4))
    run = tmp_path / "warm"
    write_warm_start(first / "latest", run / "warm_start")
    kept = weights(run / "warm_start.safetensors")
    assert {v.dtype for v in kept.values() if v.is_floating_point()} == {torch.float16}
    for k, v in weights(first / "latest.safetensors").items():   # rounded once to float16, nothing else
        torch.testing.assert_close(kept[k].float(), v, rtol=1e-3, atol=1e-4)

    res = train_vae(corpus, run, tiny_vae_config(), vae_train_config(warmup_steps=2, milestones=()), resume=True)
    assert res.step == 6 and res.epoch == 2                     # 3 batches per epoch: step 4 is epoch 1, batch 1
    rows = [json.loads(l) for l in (run / "log.jsonl").read_text().splitlines()]
    assert rows[0]["step"] == 4 and rows[0]["warm_start"].endswith("latest")
    lrs = {r["step"]: r["lr"] for r in rows if "lr" in r}
    assert sorted(lrs) == [5, 6]
    assert lrs[5] == pytest.approx(3e-3 * 0.5) and lrs[6] == pytest.approx(3e-3)   # warmed up again over 2 steps
    st = load_train_state(run)
    assert st.step == 6 and st.extra["warm_from"] == 4
    assert rewarm_factor(4, None, 2) == 1.0 and rewarm_factor(4, 4, 0) == 1.0 and rewarm_factor(9, 4, 2) == 1.0
    # the warm start moved the model from the kept weights, and the weights differ from the exact run's
    moved = weights(run / "latest.safetensors")
    assert any(not torch.equal(moved[k], kept[k].float()) for k in kept if kept[k].is_floating_point())
    # once the run has a train state, the warm start is ignored (an exact resume)
    again = train_vae(corpus, run, tiny_vae_config(), vae_train_config(max_steps=7, warmup_steps=2, milestones=()),
                      resume=True)
    assert again.step == 7 and load_train_state(run).extra["warm_from"] == 4
    # a warm start of another model configuration is refused with the fields that differ
    other = tmp_path / "other"
    write_warm_start(first / "latest", other / "warm_start")
    with pytest.raises(CheckpointError, match="latent_dim"):
        train_vae(corpus, other, tiny_vae_config().__class__(latent_dim=4, n_extra_layers=0), vae_train_config(), resume=True)
    assert load_warm_start(tmp_path / "nothing", "vae", tiny_vae_config()) is None


def test_disk_full_keeps_the_previous_checkpoint(corpus, tmp_path, monkeypatch):
    train_vae(corpus, tmp_path, tiny_vae_config(), vae_train_config(max_steps=2))
    kept = ("latest.json", "latest.safetensors", "train_state.json", "train_state.safetensors", "mean_std.safetensors")
    before = {p.name: p.read_bytes() for p in tmp_path.iterdir() if p.name in kept}
    assert len(before) == len(kept)
    import safetensors.torch

    real = safetensors.torch.save_file

    def full_disk(tensors, filename, metadata=None):
        Path(filename).write_bytes(b"\0" * 100)  # a partial write, then the disk is full
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(safetensors.torch, "save_file", full_disk)
    with pytest.raises(OSError) as info:
        train_vae(corpus, tmp_path, tiny_vae_config(), vae_train_config(max_steps=4), resume=True)
    assert info.value.errno == errno.ENOSPC
    assert {p.name: p.read_bytes() for p in tmp_path.iterdir() if p.name in kept} == before  # nothing replaced
    assert sorted(p.name for p in tmp_path.iterdir() if p.name not in kept) == ["config.json", "log.jsonl"]  # no temp file
    monkeypatch.setattr(safetensors.torch, "save_file", real)
    assert load_train_state(tmp_path).step == 2
    res = train_vae(corpus, tmp_path, tiny_vae_config(), vae_train_config(max_steps=4), resume=True)
    assert res.step == 4


def test_refuses_to_overwrite_a_run_and_resume_without_state_starts_fresh(corpus, straight_vae, tmp_path):
    with pytest.raises(FileExistsError, match="resume=True"):
        train_vae(corpus, straight_vae, tiny_vae_config(), vae_train_config())
    res = train_vae(corpus, tmp_path, tiny_vae_config(), vae_train_config(max_steps=1), resume=True)
    assert res.step == 1 and (tmp_path / "train_state.safetensors").is_file()


def test_batch_size_must_split_evenly_and_fit_the_data(corpus, tmp_path):
    with pytest.raises(ValueError, match="not divisible"):
        fit(scalar_task(), tmp_path, VAETrainConfig(batch_size=3, max_steps=1, progress=False),
            env=DistEnv(rank=0, world_size=2))
    with pytest.raises(ValueError, match="fewer than one batch"):
        train_vae(corpus, tmp_path / "b", tiny_vae_config(), vae_train_config(batch_size=4096))


# ---------------------------------------------------------------------------- denoiser
@pytest.fixture(scope="module")
def tiny_vae_run(corpus, tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("vae_for_denoiser")
    train_vae(corpus, out, tiny_vae_config(), vae_train_config(max_steps=0))  # initial weights suffice
    return out


def tiny_denoiser_config():
    from salad_core.models.denoiser import DenoiserConfig

    return DenoiserConfig(latent_dim=8, width=16, heads=2, ff_dim=32, layers=1, text_dim=16)


def den_train_config(**kw) -> DenoiserTrainConfig:
    base = dict(batch_size=4, max_steps=4, lr=2e-3, warmup_steps=1, max_length=72, cond_drop_prob=0.3,
                val_every=2, ckpt_every=0, log_every=1, num_threads=1, progress=False, seed=11)
    base.update(kw)
    return DenoiserTrainConfig(**base)


def test_denoiser_resume_is_bit_identical(corpus, tiny_vae_run, tmp_path):
    ref = tmp_path / "ref"
    res = train_denoiser(corpus, ref, tiny_vae_run, tiny_denoiser_config(), den_train_config(), HashTextEncoder())
    assert res.step == 4 and res.best_step is not None
    doc, _ = read_checkpoint(ref / "latest")
    assert doc["type"] == "denoiser" and doc["meta"]["diffusion"]["prediction_type"] == "v_prediction"
    assert (ref / "best.safetensors").is_file()
    run = tmp_path / "run"
    train_denoiser(corpus, run, tiny_vae_run, tiny_denoiser_config(), den_train_config(max_steps=1), HashTextEncoder())
    res2 = train_denoiser(corpus, run, tiny_vae_run, tiny_denoiser_config(), den_train_config(), HashTextEncoder(),
                          resume=True)
    assert res2.step == 4 and res2.best_val == res.best_val
    assert_same_tensors(weights(run / "latest.safetensors"), weights(ref / "latest.safetensors"))
    assert_same_tensors(weights(run / "best.safetensors"), weights(ref / "best.safetensors"))


def test_a_runs_validation_does_not_depend_on_whether_it_was_resumed(corpus, tiny_vae_run, tmp_path):
    """Session 32's defect: the fused AdamW does not bump the weights' version counters, so the no-grad caches
    (stacked Q/K/V, text keys/values) kept the weights of a run's first validation and every later validation of
    the same process used them; a resumed run (new model, new caches) validated the same step differently."""
    val = {}
    for name, stops in (("straight", [4]), ("resumed", [2, 4])):
        for i, steps in enumerate(stops):
            train_denoiser(corpus, tmp_path / name, tiny_vae_run, tiny_denoiser_config(),
                           den_train_config(max_steps=steps, adamw="fused", lr=2e-2), HashTextEncoder(),
                           resume=i > 0)
        rows = [json.loads(line) for line in (tmp_path / name / "log.jsonl").read_text().splitlines()]
        val[name] = {r["step"]: r["val_loss"] for r in rows if "val_loss" in r}
    assert set(val["straight"]) == {2, 4}
    assert val["straight"][2] != val["straight"][4]                     # the weights did move between them
    assert val["straight"] == pytest.approx(val["resumed"], rel=1e-6, abs=1e-7)


def test_optimizer_step_lets_the_no_grad_caches_see_a_fused_update():
    from salad_core.models.denoiser import Denoiser
    from salad_core.train.common import optimizer_step
    from salad_core.train.config import make_adamw

    torch.manual_seed(0)
    model = Denoiser(tiny_denoiser_config())
    x, t = torch.randn(2, 3, 7, 8), torch.tensor([10, 500])
    text, mask = torch.randn(2, 4, 16), torch.ones(2, 4, dtype=torch.bool)
    params = [p for p in model.parameters() if p.requires_grad]
    opt = make_adamw(params, den_train_config(adamw="fused"), lr=5e-2)
    model.eval()
    with torch.no_grad():
        model(x, t, text, text_mask=mask)                                # builds the caches
    model(x, t, text, text_mask=mask).square().mean().backward()
    optimizer_step(opt, params)
    with torch.no_grad():
        after = model(x, t, text, text_mask=mask)
        want = Denoiser(tiny_denoiser_config()).eval()                   # the same weights, no cache yet
        want.load_state_dict(model.state_dict())
        assert torch.allclose(after, want(x, t, text, text_mask=mask), atol=1e-6)


def test_denoiser_batch_prep_drops_captions_masks_and_targets(corpus, tiny_vae_run):
    from salad_core.data.dataset import MotionTextDataset, collate_motion_text
    from salad_core.sampling import make_scheduler
    from salad_core.train.common import StepContext
    from salad_core.train.denoiser_trainer import (CaptionFeatureCache, DenoiserObjective, load_frozen_vae,
                                                   prepare_denoiser_batch)

    vae = load_frozen_vae(tiny_vae_run)
    assert not any(p.requires_grad for p in vae.parameters()) and not vae.training
    ds = MotionTextDataset(corpus, "train", max_length=72, seed=0)
    batch = collate_motion_text([ds[i] for i in range(len(ds))] * 25, trim=False)   # 200 samples
    batch["length"][0] = 40                                                         # one short motion
    enc = HashTextEncoder()
    sched = make_scheduler()
    cfg = den_train_config(cond_drop_prob=0.25)
    ctx = StepContext(GlobalBatchRandom(torch.Generator().manual_seed(0), DistEnv()), DistEnv(), train=True, step=0)
    inp = prepare_denoiser_batch(batch, ctx, vae=vae, text=CaptionFeatureCache(enc, 100), scheduler=sched,
                                 config=cfg, prediction_type="v_prediction", latent_shape=(18, 7, 8))
    n_lat = int(batch["length"].max()) // 4
    assert inp["noisy"].shape == (200, n_lat, 7, 8) and inp["frame_mask"].shape == (200, n_lat)
    assert torch.equal(inp["frame_mask"], torch.arange(n_lat)[None] < (batch["length"] // 4)[:, None])
    assert inp["frame_mask"][0].sum() == 10
    assert torch.all(inp["noisy"][0, 10:] == 0) and torch.all(inp["target"][0, 10:] == 0)  # padded frames masked
    frac = float(((inp["text_mask"].sum(1) == 2)).float().mean())  # [CLS] [SEP] only: the null text ""
    assert 0.15 < frac < 0.35, frac                                       # about cond_drop_prob
    assert int(inp["timesteps"].min()) >= 0 and int(inp["timesteps"].max()) < 1000
    # same seed, same draws; validation keeps every caption
    ctx2 = StepContext(GlobalBatchRandom(torch.Generator().manual_seed(0), DistEnv()), DistEnv(), train=False, step=0)
    val = prepare_denoiser_batch(batch, ctx2, vae=vae, text=CaptionFeatureCache(enc, 0), scheduler=sched,
                                 config=cfg, prediction_type="v_prediction", latent_shape=(18, 7, 8))
    assert torch.equal(val["noisy"], inp["noisy"]) and bool((val["text_mask"].sum(1) > 2).all())

    class Zero(nn.Module):
        def forward(self, x, t, text, text_mask, frame_mask):
            return torch.zeros_like(x)

    loss = DenoiserObjective(Zero())(**inp)["loss"]
    m = inp["frame_mask"][:, :, None, None]
    assert float(loss) == pytest.approx(float(inp["target"][m.expand_as(inp["target"])].pow(2).mean()), rel=1e-5)


def test_caption_cache_gives_the_features_of_single_encoding():
    from salad_core.train.denoiser_trainer import CaptionFeatureCache

    enc = HashTextEncoder()
    cache = CaptionFeatureCache(enc, max_entries=2)
    f1, m1 = cache.encode(["a person walks", "", "a person walks"])
    assert cache.misses == 2 and cache.hits == 1 and f1.shape == (3, 5, 16)
    assert m1.sum(1).tolist() == [5, 2, 5]
    alone = enc.encode(["a person walks"]).features[0]
    assert torch.equal(f1[0], alone) and torch.equal(f1[2], alone)
    cache.encode(["someone runs"])                       # evicts the oldest entry
    assert len(cache._store) == 2


def test_denoiser_with_the_real_minilm_encoder(corpus, tiny_vae_run, tmp_path):
    from salad_core.models.denoiser import DenoiserConfig

    cfg = DenoiserConfig(latent_dim=8, width=16, heads=2, ff_dim=32, layers=1, text_dim=384)
    res = train_denoiser(corpus, tmp_path, tiny_vae_run, cfg, den_train_config(max_steps=2, val_every=0))
    assert res.step == 2 and np.isfinite(res.last_loss)
    doc, _ = read_checkpoint(tmp_path / "latest")
    assert doc["meta"]["text_encoder"] == "minilm"
    with pytest.raises(ValueError, match="text_dim=16 does not fit"):
        train_denoiser(corpus, tmp_path / "x", tiny_vae_run, tiny_denoiser_config(), den_train_config())


def test_cli_main_trains_and_resumes(corpus, tmp_path, capsys):
    from salad_core.cli.train import main

    conf = tmp_path / "conf.json"
    conf.write_text(json.dumps({"model": {"latent_dim": 8, "n_extra_layers": 0},
                                "train": {"batch_size": 8, "max_steps": 2, "warmup_steps": 0, "num_threads": 1,
                                          "val_every": 0, "log_every": 1}}))
    out = tmp_path / "run"
    assert main(["vae", "--data", str(corpus), "--out", str(out), "--config", str(conf), "--no-progress"]) == 0
    assert load_train_state(out).step == 2
    assert main(["vae", "--data", str(corpus), "--out", str(out), "--resume", "--steps", "3", "--no-progress"]) == 0
    assert load_train_state(out).step == 3
    assert json.loads((out / "config.json").read_text())["model"]["latent_dim"] == 8
    assert "step 3" in capsys.readouterr().out


def test_denoiser_normalises_with_the_vae_statistics(corpus, tiny_vae_run, tmp_path):
    import shutil

    from salad_core.io import save_tensors

    vae_dir = tmp_path / "vae"
    shutil.copytree(tiny_vae_run, vae_dir)
    stats = load_tensors(vae_dir / "mean_std.safetensors")
    shifted = {"mean": stats["mean"] + 1.0, "std": stats["std"] * 2.0}
    save_tensors(vae_dir / "mean_std.safetensors", shifted)
    train_denoiser(corpus, tmp_path / "den", vae_dir, tiny_denoiser_config(), den_train_config(max_steps=0),
                   HashTextEncoder())
    got = load_tensors(tmp_path / "den" / "mean_std.safetensors")
    assert torch.equal(got["mean"], shifted["mean"]) and torch.equal(got["std"], shifted["std"])


def test_denoiser_trains_on_an_exported_vae_folder_with_its_statistics(corpus, tiny_vae_run, tmp_path):
    """An exported VAE (``export_vae``: vae.*, stats.safetensors; e.g. the shipped general VAE) serves as
    ``--vae``: its stats.safetensors, not the data folder's Mean/Std, normalise the motions, and the
    weights are those of the run's checkpoint."""
    from salad_core.io import save_tensors
    from salad_core.train.assemble import export_vae
    from salad_core.train.denoiser_trainer import load_frozen_vae

    run = tmp_path / "run"
    import shutil
    shutil.copytree(tiny_vae_run, run)
    stats = load_tensors(run / "mean_std.safetensors")
    shifted = {"mean": stats["mean"] - 0.5, "std": stats["std"] * 3.0}
    save_tensors(run / "mean_std.safetensors", shifted)
    folder = export_vae(run, tmp_path / "exported", dtype=None)
    assert not (folder / "mean_std.safetensors").exists() and (folder / "stats.safetensors").is_file()
    train_denoiser(corpus, tmp_path / "den", folder / "vae", tiny_denoiser_config(), den_train_config(max_steps=0),
                   HashTextEncoder())
    got = load_tensors(tmp_path / "den" / "mean_std.safetensors")
    assert torch.equal(got["mean"], shifted["mean"]) and torch.equal(got["std"], shifted["std"])
    ours, theirs = load_frozen_vae(folder / "vae").state_dict(), load_frozen_vae(run).state_dict()
    assert ours.keys() == theirs.keys() and all(torch.equal(ours[k], theirs[k]) for k in ours)


def test_assemble_from_an_exported_vae_equals_assembling_from_its_run(corpus, tiny_vae_run, tmp_path):
    """assemble_pipeline takes an exported VAE folder (or its ``vae`` stem) as it takes the VAE's run: the
    same weights, statistics, run record and numerics note, so a pipeline can be built from a shipped VAE
    after its run folder is gone."""
    from salad_core.train.assemble import assemble_pipeline, export_vae, vae_source

    den = tmp_path / "den"
    train_denoiser(corpus, den, tiny_vae_run, tiny_denoiser_config(), den_train_config(max_steps=2),
                   HashTextEncoder())
    exported = export_vae(tiny_vae_run, tmp_path / "exported", dtype=None)
    a = assemble_pipeline(tiny_vae_run, den, tmp_path / "a", dtype=None, text_encoder=HashTextEncoder())
    # a VAE trained under autocast: the note names it for the run and for its exported copy alike
    bf16_run = tmp_path / "vae_bf16"
    train_vae(corpus, bf16_run, tiny_vae_config(), vae_train_config(max_steps=0, autocast="bf16"))
    notes = [(assemble_pipeline(src, den, tmp_path / f"n{i}", dtype=None, text_encoder=HashTextEncoder())
              / "MODEL_CARD.md").read_text() for i, src in enumerate((bf16_run, export_vae(bf16_run, tmp_path / "e")))]
    assert "- **vae** (vae_bf16): forward passes under bf16 autocast" in notes[0]
    assert "- **vae** (as recorded with the exported weights): forward passes under bf16 autocast" in notes[1]
    for i, source in enumerate((exported, exported / "vae")):
        stem, stats, record, run = vae_source(source)
        assert stem == exported / "vae" and stats == exported / "stats.safetensors" and run is None
        b = assemble_pipeline(source, den, tmp_path / f"b{i}", dtype=None, text_encoder=HashTextEncoder())
        for name in ("vae.safetensors", "stats.safetensors", "denoiser.safetensors"):
            assert_same_tensors(load_tensors(a / name), load_tensors(b / name))
        assert json.loads((b / "runs.json").read_text()) == json.loads((a / "runs.json").read_text())
        card_a, card_b = (a / "MODEL_CARD.md").read_text(), (b / "MODEL_CARD.md").read_text()
        assert card_a == card_b
    with pytest.raises(FileNotFoundError, match="no such folder"):
        vae_source(tmp_path / "nothing")
    (tmp_path / "empty").mkdir()
    with pytest.raises(FileNotFoundError, match="no best/latest checkpoint"):
        vae_source(tmp_path / "empty")


def test_assemble_refuses_a_vae_the_denoiser_did_not_train_on(corpus, tiny_vae_run, tmp_path):
    """A denoiser diffuses in its own VAE's latent space: assembling it with another VAE (here one with other
    initial weights) is refused with an error naming both, while the VAE it recorded, its float16 export and
    ``vae=None`` (take the recorded one) all give the same pipeline. A run whose VAE is gone is assembled with a
    warning recorded in ``runs.json``."""
    import shutil

    from salad_core.io import save_tensors
    from salad_core.train.assemble import assemble_pipeline, check_denoiser_vae, denoiser_vae, export_vae, vae_source

    den = tmp_path / "den"
    train_denoiser(corpus, den, tiny_vae_run, tiny_denoiser_config(), den_train_config(max_steps=1), HashTextEncoder())
    assert denoiser_vae(den) == vae_source(tiny_vae_run).stem
    other = tmp_path / "other_vae"
    train_vae(corpus, other, tiny_vae_config(), vae_train_config(max_steps=0, seed=4))
    with pytest.raises(ValueError, match=r"is not the VAE denoiser run .* trained on .*weight '"):
        assemble_pipeline(other, den, tmp_path / "bad", dtype=None, text_encoder=HashTextEncoder())
    assert not (tmp_path / "bad" / "pipeline.json").exists()
    # the same weights under other Mean/Std: refused too (the latents depend on the normalisation)
    shifted = tmp_path / "shifted"
    shutil.copytree(tiny_vae_run, shifted)
    stats = load_tensors(shifted / "mean_std.safetensors")
    save_tensors(shifted / "mean_std.safetensors", {"mean": stats["mean"] + 1.0, "std": stats["std"]})
    with pytest.raises(ValueError, match="statistic 'mean' differs"):
        assemble_pipeline(shifted, den, tmp_path / "bad2", dtype=None, text_encoder=HashTextEncoder())
    half = export_vae(tiny_vae_run, tmp_path / "half", dtype=torch.float16)
    assert check_denoiser_vae(vae_source(half), den) == "same"
    a = assemble_pipeline(None, den, tmp_path / "a", dtype=None, text_encoder=HashTextEncoder())
    b = assemble_pipeline(tiny_vae_run, den, tmp_path / "b", dtype=None, text_encoder=HashTextEncoder())
    for name in ("vae.safetensors", "stats.safetensors", "denoiser.safetensors"):
        assert_same_tensors(load_tensors(a / name), load_tensors(b / name))
    assert json.loads((a / "runs.json").read_text())["vae_check"] == "same"
    # the recorded VAE is gone (a run folder from another machine): assembled, and the record says it was unchecked
    moved = tmp_path / "moved_vae"
    shutil.copytree(tiny_vae_run, moved)
    config = json.loads((den / "config.json").read_text())
    config["task"]["vae"] = str(tmp_path / "gone" / "best")
    (den / "config.json").write_text(json.dumps(config))
    c = assemble_pipeline(moved, den, tmp_path / "c", dtype=None, text_encoder=HashTextEncoder())
    assert json.loads((c / "runs.json").read_text())["vae_check"].startswith("unchecked: the denoiser's VAE")
    assert_same_tensors(load_tensors(c / "vae.safetensors"), load_tensors(b / "vae.safetensors"))
    del config["task"]["vae"]
    (den / "config.json").write_text(json.dumps(config))
    with pytest.raises(ValueError, match="does not record its VAE"):
        assemble_pipeline(None, den, tmp_path / "d", dtype=None, text_encoder=HashTextEncoder())


def test_every_vae_location_resolves_to_the_same_weights_and_statistics(corpus, tiny_vae_run, tmp_path):
    """vae_source is the one resolver: the denoiser trainer (load_frozen_vae, vae_statistics) and export_vae
    accept a run folder, a checkpoint stem or file in it, an exported VAE folder or its stem, and a pipeline
    folder, and all give the same weights and Mean/Std (the lab's measure_vae_real.py reads them alike:
    lab/tests/test_measure_vae_real.py)."""
    from salad_core.train.assemble import assemble_pipeline, export_vae, vae_source
    from salad_core.train.denoiser_trainer import load_frozen_vae, vae_statistics

    den = tmp_path / "den"
    train_denoiser(corpus, den, tiny_vae_run, tiny_denoiser_config(), den_train_config(max_steps=1), HashTextEncoder())
    exported = export_vae(tiny_vae_run, tmp_path / "exported", dtype=None)
    pipeline = assemble_pipeline(tiny_vae_run, den, tmp_path / "pipe", dtype=None, text_encoder=HashTextEncoder())
    stem = vae_source(tiny_vae_run).stem
    assert stem.parent == tiny_vae_run and stem.name in ("best", "latest")
    want = load_frozen_vae(tiny_vae_run).state_dict()
    want_mean, want_std = vae_statistics(tiny_vae_run)
    locations = [tiny_vae_run, stem, stem.with_suffix(".safetensors"), stem.with_suffix(".json"), exported,
                 exported / "vae", exported / "vae.safetensors", pipeline, pipeline / "vae"]
    for where in locations:
        source = vae_source(where)
        assert source.has_stats, where
        assert (source.run == tiny_vae_run) == (where in locations[:4]), where
        assert source.record["config"] == json.loads((tiny_vae_run / "config.json").read_text()), where
        assert_same_tensors(load_frozen_vae(where).state_dict(), want)
        mean, std = vae_statistics(where)
        np.testing.assert_array_equal(mean, want_mean)
        np.testing.assert_array_equal(std, want_std)
    again = export_vae(exported, tmp_path / "re-exported", dtype=None)      # an exported VAE exports again
    assert_same_tensors(load_tensors(again / "vae.safetensors"), load_tensors(exported / "vae.safetensors"))
    assert json.loads((again / "runs.json").read_text()) == json.loads((exported / "runs.json").read_text())
    with pytest.raises(FileNotFoundError, match="no such folder"):
        vae_source(tmp_path / "exported" / "missing")
    (tmp_path / "nostats").mkdir()
    for name in ("vae.json", "vae.safetensors"):
        (tmp_path / "nostats" / name).write_bytes((exported / name).read_bytes())
    assert vae_statistics(tmp_path / "nostats") == (None, None)


def test_vae_then_denoiser_on_the_procedural_corpus(tmp_path):
    from salad_core.data.procedural import build_corpus

    root = tmp_path / "corpus"
    build_corpus(root, size="tiny", seed=0, progress=False)
    vae = train_vae(root, tmp_path / "vae", tiny_vae_config(),
                    vae_train_config(batch_size=16, max_steps=3, val_every=3, val_batches=2))
    assert vae.step == 3 and vae.best_step == 3 and np.isfinite(vae.best_val)
    den = train_denoiser(root, tmp_path / "den", tmp_path / "vae", tiny_denoiser_config(),
                         den_train_config(batch_size=8, max_steps=3, max_length=196, val_every=3, val_batches=2),
                         HashTextEncoder())
    assert den.step == 3 and den.best_step == 3 and np.isfinite(den.best_val)
    doc, _ = read_checkpoint(tmp_path / "den" / "best")
    assert doc["meta"]["vae"] == str(tmp_path / "vae" / "best")  # the denoiser used the VAE's best weights


def test_caption_cache_prefill_matches_single_encoding():
    """Prefilled (batched) caption features equal one-by-one encoding and leave no misses."""
    from salad_core.text import load_text_encoder
    from salad_core.train.denoiser_trainer import CaptionFeatureCache

    enc = load_text_encoder("minilm")
    caps = ["a person walks forward", "someone waves", "a man jumps high and then sits on the ground", ""]
    alone = CaptionFeatureCache(enc, 100)
    ref = {c: alone._one(c) for c in caps}
    cache = CaptionFeatureCache(enc, 100)
    assert cache.prefill(caps + caps, batch_size=3) == 4
    feats, mask = cache.encode(caps)
    assert cache.misses == 0 and cache.hits == 4
    for i, c in enumerate(caps):
        assert torch.allclose(feats[i, mask[i]], ref[c], atol=1e-5)
    assert CaptionFeatureCache(enc, 2).prefill(caps) == 0       # would not fit: left to the LRU path


def test_run_config_records_batching_threads_numerics_and_the_card_says_so(corpus, tiny_vae_run, tmp_path):
    from salad_core.train.assemble import assemble_pipeline, numerics_note, write_numerics_section

    new = tmp_path / "new"
    res = train_denoiser(corpus, new, tiny_vae_run, tiny_denoiser_config(), den_train_config(max_steps=2),
                         HashTextEncoder())
    assert res.threads == 1 and res.frames_per_s > 0
    doc = json.loads((new / "config.json").read_text())
    assert doc["runtime"]["torch_threads"] == 1 and doc["runtime"]["batching"] == "random"
    assert doc["runtime"]["micro_batches"] == 4                       # the denoiser's default
    assert doc["task"]["numerics"]["latents"].startswith("cached")
    assert (new / "latent_cache").is_dir()
    lines = [r for r in map(json.loads, (new / "log.jsonl").read_text().splitlines()) if "lr" in r]
    assert len(lines) == 2 and all(r["threads"] == 1 and r["frames_per_s"] > 0 for r in lines)
    old = tmp_path / "old"
    train_denoiser(corpus, old, tiny_vae_run, tiny_denoiser_config(),
                   den_train_config(max_steps=2, batching="random", latent_cache=False, micro_batches=1),
                   HashTextEncoder())
    assert numerics_note({"denoiser": old}) is None and not (old / "latent_cache").exists()
    note = numerics_note({"vae": tiny_vae_run, "denoiser": new})
    assert "**denoiser**" in note and "4 length-sorted micro-batches" in note and "**vae**" not in note
    card = tmp_path / "MODEL_CARD.md"
    card.write_text("# My model\n\nhand-written text\n")
    write_numerics_section(card, note)
    write_numerics_section(card, note)                                  # replaced, not appended twice
    text = card.read_text()
    assert text.startswith("# My model") and text.count("## Training numerics") == 1
    write_numerics_section(card, None)
    assert "Training numerics" not in card.read_text() and "hand-written text" in card.read_text()
    pipe = assemble_pipeline(tiny_vae_run, new, tmp_path / "pipe", text_encoder=HashTextEncoder())
    assert "## Training numerics" in (pipe / "MODEL_CARD.md").read_text()


def test_resuming_a_run_from_before_buckets_keeps_its_numerics(corpus, tiny_vae_run, tmp_path, monkeypatch):
    """A run folder whose config.json predates the batching/latent-cache fields resumes with random
    batches and the VAE per step (its own numerics), not today's defaults."""
    from salad_core.cli import train as cli

    seen = {}

    def fake_train(data, out, vae, model_config, train_config, *a, **kw):
        seen["config"] = train_config
        raise SystemExit(0)

    monkeypatch.setattr("salad_core.train.denoiser_trainer.train_denoiser", fake_train)
    run = tmp_path / "old_run"
    run.mkdir()
    old = {k: v for k, v in json.loads(json.dumps(den_train_config().__dict__, default=list)).items()
           if k not in ("batching", "bucket_pool", "latent_cache", "latent_cache_dir", "latent_cache_dtype")}
    (run / "config.json").write_text(json.dumps({"model_type": "denoiser", "train": old,
                                                 "task": {"vae": str(tiny_vae_run)}}))
    with pytest.raises(SystemExit):
        cli.main(["denoiser", "--data", str(corpus), "--out", str(run), "--resume"])
    assert seen["config"].batching == "random" and seen["config"].latent_cache is False
    new_run = tmp_path / "new_run"
    new_run.mkdir()
    (new_run / "config.json").write_text(json.dumps({"model_type": "denoiser", "runtime": {},
                                                     "train": {**old, "batching": "buckets"},
                                                     "task": {"vae": str(tiny_vae_run)}}))
    with pytest.raises(SystemExit):
        cli.main(["denoiser", "--data", str(corpus), "--out", str(new_run), "--resume"])
    assert seen["config"].batching == "buckets" and seen["config"].latent_cache is True


def test_a_run_from_before_the_adamw_field_resumes_with_the_loop(corpus, tiny_vae_run, tmp_path, monkeypatch):
    """A run folder whose config.json has no ``adamw`` trained with PyTorch's per-tensor loop and resumes with
    it; a run that recorded its implementation keeps it; a new run gets the fused default."""
    from salad_core.cli import train as cli

    seen = {}

    def fake_train(data, out, vae, model_config, train_config, *a, **kw):
        seen["config"] = train_config
        raise SystemExit(0)

    monkeypatch.setattr("salad_core.train.denoiser_trainer.train_denoiser", fake_train)
    train = {k: v for k, v in json.loads(json.dumps(den_train_config().__dict__, default=list)).items() if k != "adamw"}
    for name, recorded, want in (("old", None, "loop"), ("foreach", "foreach", "foreach"), ("fused", "fused", "fused")):
        run = tmp_path / name
        run.mkdir()
        section = train if recorded is None else {**train, "adamw": recorded}
        (run / "config.json").write_text(json.dumps({"model_type": "denoiser", "runtime": {}, "train": section,
                                                     "task": {"vae": str(tiny_vae_run)}}))
        with pytest.raises(SystemExit):
            cli.main(["denoiser", "--data", str(corpus), "--out", str(run), "--resume"])
        assert seen["config"].adamw == want, name
    assert cli._keep_own_optimizer({"pst": {"train": {"lr": 1e-4}}}, "keymotion")["train"] == {"adamw": "loop"}
    assert DenoiserTrainConfig().adamw == VAETrainConfig().adamw == "fused"


def test_vae_with_general_motion_bone_term_and_latent_noise(corpus, tmp_path):
    """The issue-21 recipe: corpus + general motion at a ratio, mixture statistics, a bone-length
    term and latent noise; it trains, logs the bone term, stores the mixture's statistics and resumes
    bit for bit."""
    from salad_core.data.general_dataset import mixture_mean_std
    from salad_core.data.procedural.general_build import build_general
    from salad_core.io import load_tensors
    from salad_core.models.vae import VAEConfig

    general = tmp_path / "general"
    build_general(general, n=20, seed=0, workers=1, progress=False)
    model = VAEConfig(latent_dim=8, n_extra_layers=0, dropout=0.0, lambda_bone=1.0, latent_noise=0.2)
    cfg = vae_train_config(max_steps=4, general_data=str(general), general_ratio=0.5)
    train_vae(corpus, tmp_path / "a", model, cfg)
    rows = [json.loads(line) for line in (tmp_path / "a" / "log.jsonl").read_text().splitlines()]
    assert all(r["bone"] > 0 for r in rows)
    stats = load_tensors(tmp_path / "a" / "mean_std.safetensors")
    mean, std = mixture_mean_std(corpus, general, 0.5)
    np.testing.assert_allclose(stats["mean"].numpy(), mean, rtol=1e-6)
    np.testing.assert_allclose(stats["std"].numpy(), std, rtol=1e-6)
    config = json.loads((tmp_path / "a" / "config.json").read_text())
    assert "general" in json.dumps(config)
    # exact resume with the mixture and the extra noise draws
    train_vae(corpus, tmp_path / "b", model, vae_train_config(max_steps=2, general_data=str(general)))
    train_vae(corpus, tmp_path / "b", model, vae_train_config(max_steps=4, general_data=str(general)), resume=True)
    assert_same_tensors(weights(tmp_path / "a" / "latest.safetensors"), weights(tmp_path / "b" / "latest.safetensors"))
    with pytest.raises(ValueError, match="general_ratio"):
        vae_train_config(general_ratio=1.0)


def test_denoiser_latent_norm_trains_on_normalised_latents_and_assembles(corpus, tiny_vae_run, tmp_path):
    from salad_core.data.dataset import MotionTextDataset
    from salad_core.io import load_tensors
    from salad_core.pipeline import SaladPipeline
    from salad_core.train.assemble import assemble_pipeline
    from salad_core.train.denoiser_trainer import denoiser_latent_stats, load_frozen_vae

    run = tmp_path / "run"
    train_denoiser(corpus, run, tiny_vae_run, tiny_denoiser_config(), den_train_config(latent_norm=True),
                   HashTextEncoder())
    stats = load_tensors(run / "latent_stats.safetensors")
    vae = load_frozen_vae(tiny_vae_run)
    assert stats["latent_mean"].shape == stats["latent_std"].shape == (vae.num_parts, vae.latent_dim)
    # the statistics are those of the training clips' latents: recomputed by hand
    ds = MotionTextDataset(corpus, "train", max_length=196, unit_length=vae.downsample,
                           mean=load_tensors(tiny_vae_run / "mean_std.safetensors")["mean"].numpy(),
                           std=load_tensors(tiny_vae_run / "mean_std.safetensors")["std"].numpy())
    mus, variances = [], []
    seen = set()
    for mid, offset, length in ds.crops():
        if mid in seen:
            continue
        seen.add(mid)
        clip = torch.from_numpy(ds.crop_features(mid, offset, length))[None]
        enc = vae.encode(clip[:, : (length // vae.downsample) * vae.downsample], sample=False)
        mus.append(enc.mu[0].reshape(-1, vae.num_parts, vae.latent_dim))
        variances.append(enc.logvar[0].exp().reshape(-1, vae.num_parts, vae.latent_dim))
    mu, var = torch.cat(mus).double(), torch.cat(variances).double()
    want_std = (mu.var(0, unbiased=False) + var.mean(0)).sqrt()
    torch.testing.assert_close(stats["latent_mean"], mu.mean(0).float(), atol=1e-5, rtol=1e-4)
    torch.testing.assert_close(stats["latent_std"], want_std.float(), atol=1e-5, rtol=1e-4)
    torch.testing.assert_close(denoiser_latent_stats(vae, ds)[1], stats["latent_std"])
    # the pipeline assembled from the runs diffuses in the same normalised space
    out = assemble_pipeline(tiny_vae_run, run, tmp_path / "pipe", dtype=None, text_encoder=HashTextEncoder())
    pipe = SaladPipeline.from_pretrained(out, text_encoder=HashTextEncoder())
    torch.testing.assert_close(pipe.latent_stats[0], stats["latent_mean"])
    assert json.loads((run / "config.json").read_text())["task"]["numerics"]["latent_norm"].startswith("per part")


def test_micro_batches_give_the_batch_loss_and_gradient(corpus, tiny_vae_run):
    """Length-sorted micro-batches, each trimmed to its longest item, sum to the unsplit batch's loss
    and gradient (the denoiser's key-padding masks make every item independent of trimmed frames)."""
    from salad_core.data.dataset import MotionTextDataset, collate_motion_text
    from salad_core.models.denoiser import Denoiser, DenoiserConfig
    from salad_core.sampling import make_scheduler
    from salad_core.train.common import StepContext
    from salad_core.train.denoiser_trainer import (CaptionFeatureCache, DenoiserObjective, load_frozen_vae,
                                                   prepare_denoiser_batch, split_denoiser_inputs)

    torch.manual_seed(0)
    vae = load_frozen_vae(tiny_vae_run)
    ds = MotionTextDataset(corpus, "train", max_length=72, seed=0)
    batch = collate_motion_text([ds[i] for i in range(len(ds))] * 2, trim=False)
    pattern = [72, 40, 56, 44, 64, 48, 68, 52]
    batch["length"] = torch.tensor([pattern[i % 8] for i in range(len(batch["length"]))])
    enc = HashTextEncoder()
    ctx = StepContext(GlobalBatchRandom(torch.Generator().manual_seed(0), DistEnv()), DistEnv(), train=True, step=0)
    inp = prepare_denoiser_batch(batch, ctx, vae=vae, text=CaptionFeatureCache(enc, 100), scheduler=make_scheduler(),
                                 config=den_train_config(), prediction_type="v_prediction", latent_shape=(18, 7, 8))
    model = Denoiser(DenoiserConfig(latent_dim=8, width=16, heads=2, ff_dim=32, layers=1, dropout=0.0,
                                    text_dim=enc.dim, max_len=18 * 7))
    obj = DenoiserObjective(model)
    whole = obj(**inp)["loss"]
    g_whole = torch.autograd.grad(whole, list(model.parameters()))
    parts = split_denoiser_inputs(inp, 3)
    assert len(parts) == 3 and sum(p["noisy"].shape[0] for p in parts) == len(batch["length"])
    assert [p["noisy"].shape[1] for p in parts] == sorted(p["noisy"].shape[1] for p in parts)
    assert parts[0]["noisy"].shape[1] < inp["noisy"].shape[1]         # the short group is trimmed
    losses = [obj(**p)["loss"] for p in parts]
    torch.testing.assert_close(sum(losses), whole, rtol=1e-5, atol=1e-7)
    g_parts = [torch.autograd.grad(l, list(model.parameters())) for l in losses]
    for i, g in enumerate(g_whole):
        torch.testing.assert_close(sum(gp[i] for gp in g_parts), g, rtol=1e-4, atol=1e-6)


def test_the_card_says_when_a_run_trained_under_autocast(tmp_path):
    from salad_core.train.assemble import numerics_note

    run = tmp_path / "vae"
    run.mkdir()
    (run / "config.json").write_text(json.dumps({"runtime": {"batching": "random", "autocast": "bf16",
                                                             "torch_threads": 2}}))
    note = numerics_note({"vae": run})
    assert "**vae** (vae): forward passes under bf16 autocast" in note and "2 torch thread(s)" in note
    assert "`autocast: null`" in note
    (run / "config.json").write_text(json.dumps({"runtime": {"batching": "random", "autocast": None}}))
    assert numerics_note({"vae": run}) is None
