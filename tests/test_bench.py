"""salad_core.bench: the FLOP count against a hand count and torch's counter, and tiny runs of the
measuring helpers (``salad bench --quick`` itself takes a minute and is not run here); the package's
entry points (``salad bench``, ``python -m salad_core.bench``)."""
from __future__ import annotations

import datetime
import os
import platform
import time

import numpy as np
import pytest
import torch

from salad_core import bench
from salad_core.cli import bench as bench_cli
from salad_core.models.denoiser import Denoiser, DenoiserConfig

TINY = DenoiserConfig(latent_dim=4, num_parts=7, width=8, heads=2, ff_dim=16, layers=3, text_dim=6)


@pytest.fixture(scope="module")
def tiny_pipe(make_tiny_pipeline, single_thread):
    return make_tiny_pipeline(seed=0)


def test_gemm_flops_matches_a_hand_count():
    # Dz=4, P=7, w=8, f=16, L=3 (1 skip), C=6; 2 rows, 3 latent frames -> n = 21 tokens, W = 5 text tokens.
    # Multiply-adds per row:
    #   input  Linear(4,8)+Linear(8,8):        21 * (32 + 64)          = 2016
    #   output Linear(8,8)+Linear(8,4):        21 * (64 + 32)          = 2016
    #   per layer QKVO x2 + cross Q,O: 3 * 21 * 10 * 64               = 40320
    #   skip merge Linear(16, 8):          1 * 21 * 16 * 8             = 2688
    #   attention qk^T + pv: 3 * (2*21*3*8 + 2*21*7*8 + 2*21*5*8)      = 15120
    #   FFN: 3 * 21 * 8 * 16 each way                                   = 8064
    #   text once: word_emb 5*6*8 + K,V 3 * 2 * 5 * 64                  = 2160
    # Once per timestep, not per row: timestep MLP 2 x (8x8) + 12 FiLMs Linear(8,16): 128 + 12 * 128 = 1664
    fl = bench.gemm_flops(TINY, rows=2, frames=3, tokens=5)
    assert fl == {"proj": 4 * 47040, "ffn_up": 4 * 8064, "ffn_down": 4 * 8064, "attn": 4 * 15120,
                  "text_once": 4 * 2160, "timestep_once": 2 * 1664}
    # one CFG step for one motion = the 2 rows above, without the cached text and timestep work
    assert bench.step_flops(TINY, batch=1, frames=3, tokens=5) == 4 * (47040 + 2 * 8064 + 15120)
    assert bench.step_flops(TINY, batch=1, frames=3, tokens=5, guidance=False) == 2 * (47040 + 2 * 8064 + 15120)


def test_gemm_flops_equals_torch_flop_counter_on_the_real_model(single_thread):
    """With the eager attention processor and the aten dense layers (torch's counter does not see
    oneDNN's op) every product is a counted matmul: the count is exact."""
    from torch.utils.flop_counter import FlopCounterMode

    from salad_core.models.attention import EagerProcessor, use_processors
    from salad_core.models.gemm import use_backend

    torch.manual_seed(0)
    rows, frames, tokens = 4, 6, 5
    cfg = DenoiserConfig(width=32, heads=2, ff_dim=64, layers=5, text_dim=24)
    model = Denoiser(cfg).eval()
    x = torch.randn(rows, frames, cfg.num_parts, cfg.latent_dim)
    text, mask = torch.randn(rows, tokens, cfg.text_dim), torch.ones(rows, tokens, dtype=torch.bool)
    expected = bench.gemm_flops(cfg, rows, frames, tokens)
    with torch.inference_mode(), use_processors(model, EagerProcessor()), use_backend("aten"):
        ctx = model.prepare_text(text, mask)
        with FlopCounterMode(display=False) as first:
            model(x, torch.tensor([10]), text_context=ctx)         # computes and caches text K/V, timestep
        with FlopCounterMode(display=False) as again:
            model(x, torch.tensor([10]), text_context=ctx)         # a sampling step: cache hits
    assert first.get_total_flops() == sum(expected.values())
    assert again.get_total_flops() == bench.step_flops(cfg, rows // 2, frames, tokens)


def test_speed_rows_and_roofline_are_consistent(single_thread):
    torch.manual_seed(0)
    model = Denoiser(TINY).eval()
    case = bench.Case("tiny", TINY, 5)
    per_step = bench.time_denoiser_steps(model, case, batch=2, latent_frames=4, steps=3)
    assert per_step.dtype == np.float64 and per_step.shape == (3,) and (per_step > 0).all()
    speed, roof = bench.speed_rows(model, case, frames=16, batch=2, steps=3, matmul_time=0.001)
    assert (speed.measure, speed.unit, roof.unit) == ("seconds per motion", "s", "GFLOP/s")
    assert speed.setting == roof.setting == "tiny, 16 frames, batch 2"
    assert speed.note == "median of 3 timed steps x 50 (extrapolated)"
    flops = bench.step_flops(TINY, 2, 4, 5)
    assert f"{flops / 1e9:.2f} GFLOP/step" in roof.note
    assert roof.ratio > 0 and roof.reference > 0 and roof.value > 0
    assert "median of 3 step(s), each followed by its matrix products alone" in roof.note
    assert "older yardstick" in roof.note
    full, _ = bench.speed_rows(model, case, frames=16, batch=1, steps=bench.SAMPLING_STEPS, matmul_time=0.001)
    assert full.note == "all 50 steps timed"


def test_overhead_rows_time_every_variant_against_plain_generation(tiny_pipe):
    rows = bench.overhead_rows(tiny_pipe, frames=16, steps=2, rounds=1, warmup_steps=1)
    assert [r.measure for r in rows] == ["plain generation", "attention capture", "word swap", "refinement",
                                         "reweight", "mirror", "inversion"]
    plain = rows[0].value
    assert rows[0].ratio == 1.0
    for r in rows:
        assert r.setting == "16 frames, 2 steps, batch 1" and r.reference == plain and r.value > 0
        assert r.ratio == pytest.approx(r.value / plain)


def test_peak_rss_delta_sees_an_allocation():
    mib, method = bench.peak_rss_delta(lambda: np.ones(8_000_000).sum())   # 61 MiB, freed on return
    if "VmHWM" not in method:
        pytest.skip("no resettable RSS high-water mark on this platform")
    assert 50 < mib < 300
    idle, _ = bench.peak_rss_delta(lambda: None)
    assert idle < 20


def test_memory_rows_compare_step_counts(tiny_pipe):
    first, second = bench.memory_rows(tiny_pipe, frames=16, steps=(2, 8))
    assert (first.setting, second.setting) == ("16 frames, 2 steps", "16 frames, 8 steps")
    assert first.unit == "MiB" and first.value >= 0 and first.reference is None
    assert second.reference == first.value and "RSS" in second.note


def _tiny_recipe():
    from salad_core.models.vae import VAEConfig
    from salad_core.sampling import DiffusionConfig
    from salad_core.train.config import DenoiserTrainConfig, VAETrainConfig

    return bench.TrainRecipe(VAEConfig(), VAETrainConfig(batch_size=2, window=8),
                             DenoiserConfig(width=32, heads=2, ff_dim=64, layers=3, text_dim=384),
                             DenoiserTrainConfig(batch_size=2, max_length=16), DiffusionConfig(), "tiny recipe")


def test_training_rows_time_both_trainers(single_thread):
    vae, den = bench.training_rows(_tiny_recipe(), steps=1, warmup=1)
    assert (vae.measure, den.measure) == ("VAE steps/s", "denoiser steps/s")
    assert vae.setting == "batch 2 x 8 frames, latent 32"
    assert den.setting == "batch 2 x 16 frames, width 32, 3 layers"
    assert all(np.isfinite(r.value) and r.value > 0 for r in (vae, den)) and "tiny recipe" in den.note


def test_recipe_and_cases_come_from_the_weights_folder(tiny_pipe, tmp_path):
    import json

    from salad_core.io import config_to_dict

    weights = tiny_pipe.save_pretrained(tmp_path / "w")
    paper, default = bench.denoiser_cases(weights)
    assert paper.config == DenoiserConfig() and paper.tokens == 77
    assert default.config == tiny_pipe.denoiser.config
    tiny = _tiny_recipe()
    runs = {"vae": {"config": {"model": config_to_dict(tiny.vae), "train": config_to_dict(tiny.vae_train)}},
            "denoiser": {"config": {"model": config_to_dict(tiny.denoiser), "train": config_to_dict(tiny.denoiser_train),
                                    "task": {"diffusion": {"prediction_type": "epsilon"}}}}}
    (weights / "runs.json").write_text(json.dumps(runs))
    recipe = bench.train_recipe(weights)
    assert (recipe.vae_train.batch_size, recipe.vae_train.window, recipe.denoiser_train.max_length) == (2, 8, 16)
    assert recipe.denoiser == tiny.denoiser and recipe.diffusion.prediction_type == "epsilon"
    assert recipe.source == f"recipe of {weights / 'runs.json'}"


def test_run_benchmarks_prints_one_table_with_the_machine(monkeypatch, tmp_path, capsys):
    from salad_core.bench import run

    monkeypatch.setattr(run, "train_recipe", lambda weights=None: _tiny_recipe())   # where run_benchmarks looks
    threads = torch.get_num_threads()
    df = bench.run_benchmarks(quick=True, threads=1, sections=["training"])
    assert torch.get_num_threads() == threads                      # restored
    assert list(df.columns) == bench.COLUMNS and len(df) == 2
    header = df.attrs["header"]
    for part in (platform.platform(), f"{os.cpu_count()} CPUs", f"torch {torch.__version__}", "1 torch thread",
                 datetime.date.today().isoformat()):
        assert part in header
    text = bench.format_table(df)
    lines = text.splitlines()
    assert sum(line.startswith("| section | measure |") for line in lines) == 1   # one table
    assert sum(line.startswith("| training |") for line in lines) == 2
    assert "Notes:" in text and "training rates from 1 step(s)" in text

    out = tmp_path / "bench.md"
    assert bench_cli.main(["--quick", "--threads", "1", "--sections", "training", "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    written = out.read_text()
    assert written in printed and "| training | VAE steps/s |" in written
    with pytest.raises(FileExistsError, match="--force"):
        bench_cli.main(["--quick", "--sections", "training", "--out", str(out)])
    with pytest.raises(ValueError, match="unknown bench sections"):
        bench.run_benchmarks(quick=True, threads=1, sections=["nope"])
    with pytest.raises(ValueError, match="threads=0"):
        bench.run_benchmarks(quick=True, threads=0)


def test_compile_rows_report_speed_payoff_and_failure(monkeypatch):
    case = bench.Case("tiny", DenoiserConfig(width=32, heads=2, ff_dim=64, layers=1, text_dim=16), tokens=6)
    # a stand-in "compiler" that returns the model itself: same output, no gain
    monkeypatch.setattr(torch, "compile", lambda model, **kw: model)
    rows = bench.compile_rows(case, reps=2)
    assert [r.section for r in rows] == ["compile", "compile"]
    fwd, first = rows
    assert fwd.reference > 0 and fwd.value > 0 and fwd.ratio == pytest.approx(fwd.value / fwd.reference)
    assert "max |difference| 0.0e+00" in fwd.note and first.unit == "s" and first.value >= 0
    # the payoff follows from the two timings (equal models: either way, by noise)
    assert ("pays off after" in first.note) == (fwd.value < fwd.reference)

    def broken(model, **kw):
        raise RuntimeError("no C++ compiler\nmore")

    monkeypatch.setattr(torch, "compile", broken)
    (row,) = bench.compile_rows(case, reps=1)
    assert np.isnan(row.value) and "torch.compile failed (RuntimeError: no C++ compiler)" in row.note
    # opt-in: the default run does not compile
    assert "compile" not in bench.SECTIONS and "compile" in bench.OPTIONAL_SECTIONS


def test_batching_rows_time_three_ways_and_restore_max_batch(tiny_pipe):
    tiny_pipe.max_batch = 2
    rows = bench.batching_rows(tiny_pipe, frames=16, steps=1, motions=4, chunk=2)
    assert [r.measure for r in rows] == ["pipeline, one prompt at a time", "pipeline, all prompts in one batch",
                                         "pipeline, batches of 2 (the default chunk)"]
    assert all(r.value > 0 and r.unit == "s/motion" for r in rows)
    assert rows[1].ratio == pytest.approx(rows[1].value / rows[0].value)
    assert tiny_pipe.max_batch == 2
    tiny_pipe.max_batch = None                       # the tests keep glibc's allocator: chunks of 8
    rows = bench.batching_rows(tiny_pipe, frames=16, steps=1, motions=4, chunk=2)
    assert rows[2].measure == "pipeline, batches of 2" and tiny_pipe.max_batch is None


def test_prompts_and_attended_tokens_of_the_speed_rows():
    case = bench.Case("tiny", TINY, 77)
    for batch in (1, 32):
        (text, mask), (_, null_mask), noise, fm = bench.random_inputs(case, batch, latent_frames=4)
        lengths = mask.sum(1)
        lo, hi = bench.PROMPT_TOKENS
        assert text.shape == (batch, 77, TINY.text_dim) and bool(((lengths >= lo) & (lengths <= hi)).all())
        assert bool(mask[:, 0].all()) and int(null_mask.sum()) == 2             # prefix masks; null: 2 tokens
        assert bench.attended_tokens(case, batch) == int(lengths.max())
    short = bench.Case("short", TINY, 10)                                    # a width below PROMPT_TOKENS
    assert bench.attended_tokens(short, 4) <= 10


def test_step_products_are_exactly_the_counted_products(single_thread):
    """The roofline's reference work: torch's FLOP counter (aten route) sees exactly the FLOPs of
    one step (:func:`bench.step_flops` without guidance doubling), and the count returned agrees."""
    from torch.utils.flop_counter import FlopCounterMode

    rows, frames, tokens = 4, 6, 5
    run, flops = bench.step_products(TINY, rows, frames, tokens,
                                     {"proj": "aten", "ffn_up": "aten", "ffn_down": "aten"})
    with FlopCounterMode(display=False) as counter:
        run()
    assert counter.get_total_flops() == flops == bench.step_flops(TINY, rows // 2, frames, tokens)


def test_paired_step_times_alternate_steps_and_products(single_thread):
    torch.manual_seed(0)
    model = Denoiser(TINY).eval()
    calls = []
    steps, products = bench.paired_step_times(model, bench.Case("tiny", TINY, 5), batch=1, latent_frames=4, pairs=3,
                                              products=[lambda: (calls.append(1), time.sleep(0.002)),
                                                        lambda: time.sleep(0.004)])
    assert steps.shape == (3,) and products.shape == (2, 3) and len(calls) == 1 + 4   # warm-up + after every step
    assert (products[0] >= 0.002).all() and (products[1] >= 0.004).all() and (steps > 0).all()


def test_folded_step_products_replace_the_cross_attention_products(single_thread):
    from torch.utils.flop_counter import FlopCounterMode

    rows, frames, tokens, keys = 2, 6, 5, [3, 2]
    libs = {"proj": "aten", "ffn_up": "aten", "ffn_down": "aten"}
    run, flops = bench.step_products(TINY, rows, frames, tokens, libs, fold_keys=keys)
    with FlopCounterMode(display=False) as counter:
        run()
    w, h, n = TINY.width, TINY.heads, frames * TINY.num_parts
    cross = 2 * 2 * rows * n * w * w + 2 * 2 * rows * n * tokens * w     # Q/O projections + q k^T, p v
    folded = sum(2 * 2 * n * w * h * k for k in keys)
    assert counter.get_total_flops() == flops
    assert flops == bench.step_flops(TINY, rows // 2, frames, tokens) - TINY.layers * (cross - folded)
    with pytest.raises(ValueError, match="one key count per row"):
        bench.step_products(TINY, rows, frames, tokens, libs, fold_keys=[3])
    paper, default = bench.denoiser_cases()
    keys1 = bench.folded_keys(paper, 1)
    assert keys1 is not None and len(keys1) == 2 and keys1[1] == 2           # the empty prompt: 2 tokens


def test_train_profile_rows_time_every_part_before_and_after(tmp_path, single_thread):
    """The ``train`` section on a fake corpus of 40-120-frame clips with a tiny VAE and denoiser:
    every part is timed for both settings, and the micro-batches cut the padding of random batches."""
    from salad_core.io import save_checkpoint
    from salad_core.models.vae import MotionVAE, VAEConfig
    from salad_core.sampling import DiffusionConfig
    from salad_core.train.config import DenoiserTrainConfig, VAETrainConfig
    from salad_core.train.profile import PARTS
    from _doubles import HashTextEncoder, make_fake_corpus

    data = make_fake_corpus(tmp_path / "data", n_train=24, n_val=2, lengths=(40, 121))
    torch.manual_seed(0)
    vcfg = VAEConfig(latent_dim=4, n_extra_layers=0)
    save_checkpoint(tmp_path / "w" / "vae", MotionVAE(vcfg), model_type="salad_vae", config=vcfg)
    enc = HashTextEncoder(dim=6)
    recipe = bench.TrainRecipe(vcfg, VAETrainConfig(), TINY,
                               DenoiserTrainConfig(batch_size=8, max_length=120, val_every=4, val_batches=1,
                                                   vae_pad_to_max=False),
                               DiffusionConfig(), "tiny")
    rows, notes = bench.train_profile_rows(recipe, steps=3, warmup=1, data=data, weights=tmp_path / "w",
                                           text_encoder=enc)
    by = {r.measure: r for r in rows}
    assert [f"part: {p}" for p in PARTS] == [r.measure for r in rows[: len(PARTS)]]
    for p in ("data", "latents", "text", "forward", "backward", "optimizer", "validation"):
        assert by[f"part: {p}"].value > 0 and by[f"part: {p}"].reference > 0, p
    step = by["denoiser step"]
    assert step.value == pytest.approx(sum(by[f"part: {p}"].value for p in PARTS), rel=1e-9)
    assert step.ratio == pytest.approx(step.reference / step.value)
    pad = by["padding"]
    assert 1.0 <= pad.value < pad.reference                      # micro-batches pad less than whole random batches
    assert by["samples x frames/s"].value > 0 and "interleaved" in notes[0]


def test_python_dash_m_and_salad_bench_share_one_parser(monkeypatch):
    """``python -m salad_core.bench`` runs ``salad_core.cli.bench.main``; ``salad bench --help`` shows its parser."""
    import re
    import subprocess
    import sys

    monkeypatch.setenv("COLUMNS", "100")           # argparse wraps help to the terminal: the same width in both
    out = subprocess.run([sys.executable, "-m", "salad_core.bench", "--help"], capture_output=True, text=True,
                         timeout=120, env=dict(os.environ))
    assert out.returncode == 0, out.stderr
    threads = lambda text: re.sub(r"here \d+", "here N", text)  # noqa: E731  (torch threads may differ)
    assert threads(out.stdout) == threads(bench_cli.build_parser().format_help())
    assert out.stdout.startswith("usage: salad bench") and "--sections" in out.stdout
    for section in bench.SECTIONS + bench.OPTIONAL_SECTIONS:
        assert section in out.stdout


def test_step_runner_forward_runs_under_the_configs_autocast(single_thread):
    """The profiler's step is the trainer's: the objective's forward under ``config.autocast`` (bf16 here), the
    backward outside it, and every step's loss kept; a float32 config runs no autocast."""
    from torch import nn

    from salad_core.train.common import TrainTask
    from salad_core.train.config import TrainConfig
    from salad_core.train.profile import StepRunner

    class Recording(nn.Module):
        def __init__(self) -> None:
            super().__init__()
            self.lin = nn.Linear(4, 1)
            self.seen: list[tuple[bool, torch.dtype]] = []

        def forward(self, x):
            y = self.lin(x)
            self.seen.append((torch.is_autocast_enabled("cpu"), y.dtype))
            return {"loss": y.float().pow(2).mean()}

    class Items(torch.utils.data.Dataset):
        def __len__(self):
            return 16

        def __getitem__(self, i):
            return torch.full((4,), float(i))

    def build(config):
        obj = Recording()
        return TrainTask(model=obj, model_type="none", model_config=None, objective=obj, train_set=Items(),
                         val_set=None, collate=lambda items: {"motion": torch.stack(items)},
                         prepare=lambda batch, ctx: {"x": batch["motion"]})

    for autocast, want in ((None, (False, torch.float32)), ("bf16", (True, torch.bfloat16))):
        runner = StepRunner("r", build, TrainConfig(batch_size=4, num_workers=0, autocast=autocast, progress=False))
        for _ in range(3):
            runner.step(record=True)
        assert runner.task.objective.seen == [want] * 3
        assert len(runner.step_losses) == 3 and all(np.isfinite(runner.step_losses))
        assert runner.result().parts["forward"] > 0


def test_interleaved_medians_alternates_order_and_takes_medians():
    from salad_core.bench.interleave import interleaved_medians

    calls: list[str] = []
    a_times = iter([9.0, 1.0, 3.0, 2.0, 100.0])       # warm-up 9.0 is dropped; median of 1, 3, 2, 100 is 2.5
    b_times = iter([7.0, 5.0, 4.0, 6.0, 0.5])         # warm-up 7.0 dropped; median of 5, 4, 6, 0.5 is 4.5

    def first() -> float:
        calls.append("a")
        return next(a_times)

    def second() -> float:
        calls.append("b")
        return next(b_times)

    assert interleaved_medians(first, second, rounds=4) == (2.5, 4.5)
    assert "".join(calls) == "ab" + "ab" + "ba" + "ab" + "ba"
    with pytest.raises(ValueError, match="rounds"):
        interleaved_medians(first, second, rounds=0)


def test_realtime_rows_time_both_pipelines_and_say_which_realtime(tiny_pipe, tmp_path, monkeypatch):
    """Without realtime weights the section times a stand-in (lcm, the export's steps, no guidance) sharing the
    default's models and says so; given a pipeline it times that one; ratios are the measured quotients."""
    from salad_core.bench import realtime as rt
    from salad_core.train.consistency import DEFAULT_SAMPLE_STEPS

    monkeypatch.setattr("salad_core.pipeline.realtime_weights_dir", lambda: tmp_path / "missing")
    stand_in, what = rt.realtime_pipelines(tiny_pipe)
    assert what.startswith("stand-in") and str(tmp_path / "missing") in what
    assert (stand_in.solver, stand_in.num_steps, stand_in.guidance.scale) == ("lcm", DEFAULT_SAMPLE_STEPS, 1.0)
    assert stand_in.denoiser is tiny_pipe.denoiser and stand_in.vae is tiny_pipe.vae
    calls = []
    original = type(tiny_pipe).__call__

    def spy(self, *a, **kw):
        calls.append((self.solver, kw["num_steps"]))
        return original(self, *a, **kw)

    monkeypatch.setattr(type(tiny_pipe), "__call__", spy)
    rows, note = rt.realtime_rows(tiny_pipe, stand_in, frames=16, rounds=1, default_steps=3)
    assert sorted(set(calls)) == [("ddim", 3), ("lcm", None)] and len(calls) == 4   # warm-up + 1 round each
    slow, fast, target = rows
    assert slow.value > 0 and fast.value > 0 and fast.reference == slow.value
    assert fast.ratio == pytest.approx(fast.value / slow.value)
    assert target.ratio == pytest.approx(fast.value / rt.REALTIME_TARGET_S) and f"lcm {DEFAULT_SAMPLE_STEPS} steps" in fast.measure
    assert "interleaved" in note
    with pytest.raises(Exception, match="realtime"):
        rt.realtime_pipelines(tiny_pipe, tmp_path / "nowhere")       # a named folder must exist
