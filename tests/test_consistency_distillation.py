"""Latent consistency distillation (``salad_core.train.consistency``) and the few-step sampling of its students.

A tiny random teacher pipeline (VAE latent 8, a one-layer width-16 denoiser, the hashing text encoder) is saved as
a weight folder; the distillation runs a few steps on a fake corpus with one thread. Checked in numbers: LCM's
boundary condition and scalings, the teacher's guided DDIM step against :func:`~salad_core.sampling.denoise`'s
first step, the loss (zero exactly when it must be, blind to padded frames), the EMA target, exact resume, the
export -> ``from_pretrained`` round trip (the folder's solver, steps and guidance; the sampled latents equal a
hand-written consistency sampling; attention captured at every step) and the errors of a missing realtime folder
and of a bad ``num_steps`` entry.
"""
from __future__ import annotations

import hashlib
import json
from pathlib import Path

import numpy as np
import pytest
import torch

from salad_core.io import CheckpointError, load_tensors
from salad_core.models.denoiser import Denoiser, DenoiserConfig
from salad_core.models.vae import MotionVAE, VAEConfig
from salad_core.pipeline import SaladPipeline, realtime_weights_dir
from salad_core.sampling import DiffusionConfig, Guidance, denoise, make_scheduler
from salad_core.train.consistency import (
    ConsistencyPair,
    ConsistencyTrainConfig,
    boundary_scalings,
    build_consistency_task,
    consistency_function,
    export_realtime,
    lcm_grid,
    load_student,
    teacher_ddim_step,
    train_consistency,
)
from salad_core.train.common import StepContext
from salad_core.train.distributed import DistEnv, GlobalBatchRandom
from _doubles import HashTextEncoder, make_fake_corpus

pytestmark = pytest.mark.usefixtures("single_thread")

TEXT_DIM = 16
ACP = make_scheduler(DiffusionConfig(), "ddim").alphas_cumprod


# ------------------------------------------------------------------------------------------------ fixtures
@pytest.fixture(scope="module")
def encoder() -> HashTextEncoder:
    return HashTextEncoder(TEXT_DIM)


@pytest.fixture(scope="module")
def corpus(tmp_path_factory) -> Path:
    return make_fake_corpus(tmp_path_factory.mktemp("lcd_corpus"))


def tiny_teacher(encoder, corpus: Path, seed: int = 0, guidance: Guidance = Guidance(3.0)) -> SaladPipeline:
    """A random tiny pipeline (no dropout, so eval and train forwards agree) with the corpus's statistics."""
    torch.manual_seed(seed)
    vae = MotionVAE(VAEConfig(latent_dim=8, n_extra_layers=0, dropout=0.0))
    den = Denoiser(DenoiserConfig(latent_dim=8, width=16, heads=2, ff_dim=32, layers=1, text_dim=TEXT_DIM, dropout=0.0))
    return SaladPipeline(vae, den, encoder, np.load(corpus / "Mean.npy"), np.load(corpus / "Std.npy"),
                         guidance=guidance)


@pytest.fixture(scope="module")
def teacher_dir(encoder, corpus, tmp_path_factory) -> Path:
    return tiny_teacher(encoder, corpus).save_pretrained(tmp_path_factory.mktemp("teacher"), dtype=None)


def lcd_config(teacher: Path, **kw) -> ConsistencyTrainConfig:
    base = dict(teacher=str(teacher), batch_size=4, max_steps=4, lr=1e-3, warmup_steps=1, max_length=72, val_every=2,
                ckpt_every=0, log_every=1, num_threads=1, progress=False, seed=5)
    base.update(kw)
    return ConsistencyTrainConfig(**base)


@pytest.fixture(scope="module")
def straight_run(corpus, teacher_dir, encoder, tmp_path_factory) -> Path:
    """Four distillation steps in one go."""
    out = tmp_path_factory.mktemp("lcd_run")
    res = train_consistency(corpus, out, lcd_config(teacher_dir), encoder)
    assert res.step == 4 and not res.interrupted
    return out


def _digest(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def _text(encoder, prompts: list[str]):
    tb, null = encoder.encode(prompts), encoder.encode([""], allow_empty=True)
    return tb, null


# ------------------------------------------------------------------------------------- the consistency function
def test_boundary_condition_and_lcm_scalings():
    g = torch.Generator().manual_seed(0)
    x, pred = torch.randn(3, 5, 7, 8, generator=g), torch.randn(3, 5, 7, 8, generator=g)
    zero = torch.zeros(3, dtype=torch.long)
    assert torch.equal(consistency_function(pred, x, zero, ACP), x)                   # f(x, t_min = 0) = x
    # from the first grid point on, f is (almost) the model's clean estimate: c_out(19) = 1 - 3.5e-6
    t = torch.full((3,), 19)
    a = ACP[19]
    x0 = a.sqrt() * x - (1 - a).sqrt() * pred
    torch.testing.assert_close(consistency_function(pred, x, t, ACP), x0, atol=1e-4, rtol=0)
    sched = make_scheduler(DiffusionConfig(), "lcm")
    for step in (0, 19, 259, 999):
        ours = [float(v) for v in boundary_scalings(torch.tensor([step]))]
        assert ours == pytest.approx(sched.get_scalings_for_boundary_condition_discrete(step), rel=1e-12, abs=1e-15)
    # the grid the student trains on is the one the "lcm" solver samples on
    sched.set_timesteps(4)
    grid = lcm_grid(1000, 50)
    assert grid[0] == 19 and grid[-1] == 999 and set(sched.timesteps.tolist()) <= set(grid.tolist())
    # what the sampler's last (noise-free) step returns is the consistency function
    sched.set_timesteps(1)
    out = sched.step(pred, int(sched.timesteps[0]), x).prev_sample
    torch.testing.assert_close(out, consistency_function(pred, x, torch.full((3,), 999), ACP), atol=1e-6, rtol=1e-5)


@pytest.mark.parametrize("guidance", [Guidance(3.0), Guidance(3.0, rescale=0.6), Guidance(3.0, interval=(0.0, 0.5)),
                                      Guidance(3.0, threshold=0.9, threshold_bound=0.5)],
                         ids=["cfg", "rescale", "interval", "threshold"])
def test_teacher_step_is_the_samplers_guided_ddim_step(encoder, corpus, guidance):
    teacher = tiny_teacher(encoder, corpus, guidance=guidance)
    den = teacher.denoiser
    tb, null = _text(encoder, ["a person walks", "someone jumps slowly"])
    cond, uncond = den.prepare_text(tb.features, tb.mask), den.prepare_text(null.features, null.mask)
    noise = torch.randn(2, 6, 7, 8, generator=torch.Generator().manual_seed(1))
    mask = torch.tensor([[True] * 6, [True] * 4 + [False] * 2])
    first = {}

    class Stop(Exception):
        pass

    def keep_first(info, z):
        first["z"], first["t"] = z.clone(), info.timestep
        raise Stop

    x = noise * mask[:, :, None, None]
    for steps, t, prev in ((50, 980, 960), (2, 500, 0)):          # the official sampler's first step; a long one
        with pytest.raises(Stop):
            denoise(den, make_scheduler(teacher.diffusion, "ddim"), cond, uncond, noise, mask, guidance_scale=guidance,
                    num_steps=steps, callback=keep_first)
        assert first["t"] == t
        with torch.no_grad():
            ours = teacher_ddim_step(den, x, torch.tensor([t, t]), torch.tensor([prev, prev]), cond, uncond, mask,
                                     guidance, ACP)
        torch.testing.assert_close(ours, first["z"], atol=1e-5, rtol=1e-5)
    # per-item timesteps: a batch of two steps gives each item's own step
    with torch.no_grad():
        mixed = teacher_ddim_step(den, x, torch.tensor([500, 300]), torch.tensor([0, 280]), cond, uncond, mask,
                                  guidance, ACP)
        alone = teacher_ddim_step(den, x[1:], torch.tensor([300]), torch.tensor([280]),
                                  den.prepare_text(tb.features[1:], tb.mask[1:]), uncond, mask[1:], guidance, ACP)
    torch.testing.assert_close(mixed[:1], ours[:1], atol=1e-5, rtol=1e-5)
    torch.testing.assert_close(mixed[1:], alone, atol=1e-5, rtol=1e-5)
    assert not torch.allclose(mixed[1:], ours[1:], atol=1e-3)


# ----------------------------------------------------------------------------------------------- the loss
def _objective_and_inputs(encoder, corpus, teacher_dir, loss: str = "huber"):
    """A fresh objective (student = target = teacher) and one prepared batch of the corpus."""
    config = lcd_config(teacher_dir, loss=loss)
    task = build_consistency_task(corpus, config, DistEnv(), encoder)
    batch = task.collate([task.train_set[i] for i in range(4)])
    ctx = StepContext(GlobalBatchRandom(torch.Generator().manual_seed(3), DistEnv()), DistEnv(), train=True, step=0)
    inputs = task.prepare(batch, ctx)
    return task.objective, inputs


@pytest.mark.parametrize("loss", ["huber", "l2"])
def test_loss_is_zero_only_when_student_target_and_step_agree(encoder, corpus, teacher_dir, loss):
    objective, inputs = _objective_and_inputs(encoder, corpus, teacher_dir, loss)
    objective.eval()
    assert inputs["frame_mask"].sum() < inputs["frame_mask"].numel()        # the batch has padded frames
    assert bool((inputs["target_timesteps"] == (inputs["timesteps"] - 20).clamp_min(0)).all())
    identity = dict(inputs, target_timesteps=inputs["timesteps"])           # a DDIM step from t to t
    with torch.no_grad():
        assert float(objective(**identity)["loss"]) < 1e-9
        moved = float(objective(**inputs)["loss"])                       # the teacher's 20-step move
        assert moved > 1e-5
        # padded frames are outside the loss: changing them changes nothing
        pads = ~inputs["frame_mask"][:, :, None, None]
        noisy = inputs["noisy"] + 50.0 * pads * torch.randn_like(inputs["noisy"])
        assert float(objective(**dict(inputs, noisy=noisy))["loss"]) == pytest.approx(moved, rel=1e-5)
        # a student that differs from its target is penalised even on the identity step
        next(objective.pair.student.output_process.parameters()).add_(0.05)
        assert float(objective(**identity)["loss"]) > 1e-5


def test_ema_target_updates_once_per_completed_step():
    torch.manual_seed(0)
    pair = ConsistencyPair(Denoiser(DenoiserConfig(latent_dim=8, width=16, heads=2, ff_dim=32, layers=1,
                                                    text_dim=TEXT_DIM)))
    assert all(not p.requires_grad for p in pair.target.parameters())
    before = [p.clone() for p in pair.target.parameters()]
    with torch.no_grad():
        for p in pair.student.parameters():
            p.add_(1.0)
    assert not pair.update_target(0, 0.9)                                   # nothing completed yet
    assert pair.update_target(1, 0.9)
    for t, b, s in zip(pair.target.parameters(), before, pair.student.parameters()):
        torch.testing.assert_close(t, 0.9 * b + 0.1 * s)
    after_one = [p.clone() for p in pair.target.parameters()]
    assert not pair.update_target(1, 0.9)                                   # the same step again: no update
    assert all(torch.equal(a, t) for a, t in zip(after_one, pair.target.parameters()))
    pair.train()
    assert pair.student.training and not pair.target.training


def test_a_few_steps_lower_the_loss_on_a_fixed_batch_and_leave_the_teacher(encoder, corpus, teacher_dir):
    objective, inputs = _objective_and_inputs(encoder, corpus, teacher_dir)
    teacher_before = {k: v.clone() for k, v in objective.teacher.state_dict().items()}
    objective.train()
    assert not objective.teacher.training and not objective.pair.target.training and objective.pair.student.training
    opt = torch.optim.Adam([p for p in objective.parameters() if p.requires_grad], lr=2e-3)
    assert {id(p) for g in opt.param_groups for p in g["params"]} == {id(p) for p in objective.pair.student.parameters()}
    losses = []
    for step in range(30):
        loss = objective(**dict(inputs, step=step))["loss"]
        opt.zero_grad()
        loss.backward()
        opt.step()
        losses.append(float(loss.detach()))
    assert losses[-1] < 0.5 * losses[0], losses
    assert int(objective.pair.ema_step) == 29
    assert all(torch.equal(v, objective.teacher.state_dict()[k]) for k, v in teacher_before.items())


# ------------------------------------------------------------------------------------------ the training run
def test_run_trains_the_student_keeps_the_teacher_and_resumes_exactly(corpus, teacher_dir, encoder, straight_run,
                                                                       tmp_path):
    teacher_file = _digest(teacher_dir / "denoiser.safetensors")
    latest = load_tensors(straight_run / "latest.safetensors")
    teacher = load_tensors(teacher_dir / "denoiser.safetensors")
    student = {k[len("student."):]: v for k, v in latest.items() if k.startswith("student.")}
    target = {k[len("target."):]: v for k, v in latest.items() if k.startswith("target.")}
    assert sorted(student) == sorted(teacher) == sorted(target)
    assert any(not torch.equal(student[k], teacher[k]) for k in teacher)    # the student moved
    assert any(not torch.equal(target[k], teacher[k]) for k in teacher)     # and its EMA with it
    assert any(not torch.equal(target[k], student[k]) for k in teacher)
    assert int(latest["ema_step"]) == 3                                     # step 4's update waits for step 5
    assert _digest(teacher_dir / "denoiser.safetensors") == teacher_file
    config = json.loads((straight_run / "config.json").read_text())
    assert config["model_type"] == "consistency_denoiser" and config["task"]["kind"] == "consistency"
    assert config["task"]["guidance"]["scale"] == 3.0 and config["train"]["skip"] == 20
    logged = [json.loads(line) for line in (straight_run / "log.jsonl").read_text().splitlines()]
    assert [r["step"] for r in logged if "loss" in r] == [1, 2, 3, 4] and any("val_loss" in r for r in logged)
    # stop after 2 steps, resume to 4: the same student, target, EMA step and best checkpoint
    run = tmp_path / "resumed"
    train_consistency(corpus, run, lcd_config(teacher_dir, max_steps=2), encoder)
    res = train_consistency(corpus, run, lcd_config(teacher_dir), encoder, resume=True)
    assert res.step == 4
    for name in ("latest.safetensors", "best.safetensors"):
        a, b = load_tensors(run / name), load_tensors(straight_run / name)
        assert sorted(a) == sorted(b) and all(torch.equal(a[k], b[k]) for k in a), name
    # the exported EMA target has caught up with the last step
    caught_up = load_student(straight_run, "target", "latest").state_dict()
    expected = {k: 0.95 * target[k] + 0.05 * student[k] for k in target}
    for k, v in caught_up.items():
        torch.testing.assert_close(v, expected[k].to(v.dtype), atol=1e-6, rtol=1e-6)


def test_config_refuses_bad_settings():
    with pytest.raises(ValueError, match="skip"):
        ConsistencyTrainConfig(skip=0)
    with pytest.raises(ValueError, match="loss"):
        ConsistencyTrainConfig(loss="l1")
    with pytest.raises(ValueError, match="latent_norm"):
        ConsistencyTrainConfig(latent_norm=True)
    with pytest.raises(ValueError, match="ema_decay"):
        ConsistencyTrainConfig(ema_decay=1.0)
    with pytest.raises(ValueError, match="divide"):
        lcm_grid(1000, 30)


# ------------------------------------------------------------------------------------ export and sampling
@pytest.fixture(scope="module")
def exported(straight_run, encoder, tmp_path_factory) -> Path:
    return export_realtime(straight_run, tmp_path_factory.mktemp("realtime"), num_steps=2, dtype=None,
                           text_encoder=encoder)


def test_export_round_trip_samples_with_the_folders_solver_steps_and_guidance(exported, straight_run, encoder):
    from salad_core.attention import CaptureConfig

    doc = json.loads((exported / "pipeline.json").read_text())
    assert (doc["solver"], doc["num_steps"], doc["guidance"]["scale"]) == ("lcm", 2, 1.0)
    pipe = SaladPipeline.from_pretrained(exported, text_encoder=encoder)
    assert (pipe.solver, pipe.num_steps, pipe.guidance.scale) == ("lcm", 2, 1.0)
    student = load_student(straight_run, "student", "best" if (straight_run / "best.json").is_file() else "latest")
    assert all(torch.equal(a, b) for a, b in zip(pipe.denoiser.state_dict().values(), student.state_dict().values()))
    rows = []
    handle = pipe.denoiser.register_forward_pre_hook(lambda mod, args: rows.append(args[0].shape[0]))
    try:
        out = pipe(["a person walks", "someone jumps"], lengths=[40, 56], seed=7,
                   capture_attention=CaptureConfig(mode="full"))
    finally:
        handle.remove()
    assert rows == [2, 2]                                # two steps, conditional rows only (guidance baked in)
    assert out.settings["solver"] == "lcm" and out.settings["num_steps"] == 2
    # the maps of both steps are recorded, each a distribution over the tokens
    assert out.attention.num_steps == 2
    for window in ((0.0, 0.5), (0.5, 1.0)):
        cross = out.attention.select(steps=window).cross_map(1)
        assert cross.shape[:2] == (7, 14)
        np.testing.assert_allclose(cross.sum(-1), 1.0, atol=1e-3)
    # the latents are a hand-written two-step consistency sampling of the student with each sample's seeded noise
    sched = make_scheduler(pipe.diffusion, "lcm")
    sched.set_timesteps(2)
    assert sched.timesteps.tolist() == [999, 499]
    tb = encoder.encode(["a person walks", "someone jumps"])
    mask = pipe.frame_mask([40, 56], 14)
    z = pipe.make_noise([7, 8], 14) * mask[:, :, None, None]
    gens = []
    for s in (7, 8):
        g = torch.Generator().manual_seed(s)
        torch.randn(49, 7, 8, generator=g)
        gens.append(g)
    with torch.no_grad():
        for i, t in enumerate([999, 499]):
            v = pipe.denoiser(z, torch.tensor([t, t]), tb.features, tb.mask, mask)
            f = consistency_function(v, z, torch.tensor([t, t]), ACP)
            if i == 0:
                a = ACP[499]
                fresh = torch.cat([torch.randn(1, 14, 7, 8, generator=g) for g in gens])
                z = (a.sqrt() * f + (1 - a).sqrt() * fresh) * mask[:, :, None, None]
            else:
                z = f * mask[:, :, None, None]
    torch.testing.assert_close(out.latents, z, atol=1e-5, rtol=1e-5)
    # the same seed gives the same motion; another seed, another; an explicit DDIM-50 call is the teacher's sampler
    again = pipe(["a person walks", "someone jumps"], lengths=[40, 56], seed=7)
    assert torch.equal(again.latents, out.latents)
    assert not torch.allclose(pipe(["a person walks", "someone jumps"], lengths=[40, 56], seed=9).latents, out.latents)
    ddim = pipe(["a person walks"], lengths=40, seed=7, solver="ddim", num_steps=50)
    assert ddim.settings["num_steps"] == 50 and not torch.allclose(ddim.latents[0, :10], out.latents[0, :10])
    with pytest.raises(ValueError, match="num_steps=51 is more than the 50-step grid the 'lcm' solver samples on"):
        pipe("a person walks", lengths=40, num_steps=51)


def test_preset_realtime_loads_the_folder_or_names_the_missing_one(exported, encoder, tmp_path):
    pipe = SaladPipeline.from_pretrained(exported, preset="realtime", text_encoder=encoder)
    assert pipe.solver == "lcm" and pipe.num_steps == 2
    missing = tmp_path / "no_weights"
    with pytest.raises(CheckpointError, match=r"'realtime' weights are missing.*no_weights.*distill_realtime\.py"):
        SaladPipeline.from_pretrained(missing, preset="realtime")
    if not (realtime_weights_dir() / "pipeline.json").is_file():
        with pytest.raises(CheckpointError, match=r"salad_core/weights/salad_realtime.*distill_realtime\.py --data"):
            SaladPipeline.from_pretrained(preset="realtime")
    with pytest.raises(ValueError, match="preset='turbo' is unknown; known: realtime"):
        SaladPipeline.from_pretrained(preset="turbo")


@pytest.mark.parametrize("value, message", [(0, "positive integer"), (True, "int"), ("4", "int"),
                                            (51, "50-step grid"), (5000, "1000 diffusion timesteps")])
def test_a_bad_num_steps_entry_is_refused(exported, encoder, tmp_path, value, message):
    import shutil

    folder = tmp_path / "bad"
    shutil.copytree(exported, folder)
    doc = json.loads((folder / "pipeline.json").read_text())
    doc["num_steps"] = value
    (folder / "pipeline.json").write_text(json.dumps(doc))
    with pytest.raises(CheckpointError, match=f"num_steps.*{message}"):
        SaladPipeline.from_pretrained(folder, text_encoder=encoder)


def test_a_folder_without_num_steps_keeps_fifty_and_writes_none(teacher_dir, encoder, tmp_path):
    assert "num_steps" not in json.loads((teacher_dir / "pipeline.json").read_text())
    pipe = SaladPipeline.from_pretrained(teacher_dir, text_encoder=encoder)
    assert pipe.num_steps == 50 and pipe.solver == "ddim"
    assert "num_steps" not in json.loads((pipe.save_pretrained(tmp_path / "again") / "pipeline.json").read_text())
    with pytest.raises(ValueError, match="grid"):
        SaladPipeline(pipe.vae, pipe.denoiser, encoder, pipe.mean, pipe.std, solver="lcm", num_steps=80)


def test_export_refuses_a_run_that_is_not_a_distillation(teacher_dir, tmp_path):
    run = tmp_path / "run"
    run.mkdir()
    (run / "config.json").write_text(json.dumps({"task": {"kind": "denoiser"}}))
    with pytest.raises(ValueError, match="not a consistency distillation run"):
        export_realtime(run, tmp_path / "out", teacher=teacher_dir)
