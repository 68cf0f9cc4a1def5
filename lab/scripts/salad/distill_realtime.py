#!/usr/bin/env python
"""Distil a SALAD teacher into a few-step ("realtime") student by latent consistency distillation, export it, and
time it against the teacher.

The trainer is ``salad_core.train.consistency`` (LCM, Luo et al. 2023; MotionLCM, Dai et al. 2024): the student, a
copy of the teacher's denoiser, learns the consistency function of the teacher's guided DDIM ODE on the 50-step grid
(one teacher DDIM step of 20 timesteps per training step at the teacher's default guidance, pseudo-Huber loss on
the valid latent frames, EMA target 0.95). ``--export DIR`` writes a complete weight folder (the teacher's VAE,
statistics and text encoder, the student, ``pipeline.json`` with ``"solver": "lcm"``, ``"num_steps"`` and
guidance 1) that ``SaladPipeline.from_pretrained(DIR)`` samples correctly by default;
``salad_core/weights/salad_realtime`` is the folder of ``from_pretrained(preset="realtime")``.

    python lab/scripts/salad/distill_realtime.py --data CORPUS --out RUN --steps 20000 --threads 1   # train (resumable)
    python lab/scripts/salad/distill_realtime.py --data CORPUS --out RUN --steps 20000 --resume      # continue
    python lab/scripts/salad/distill_realtime.py --out RUN --export salad_core/weights/salad_realtime  # export only
    python lab/scripts/salad/distill_realtime.py --time --threads 1            # teacher DDIM-50 vs the student's steps

Cost on this project's 2-core CPU: about 700 latent-run frames a second on one thread (11 s a step at the default
batch 64 of 196-frame windows, 2.7 s at batch 16), so 20,000 steps at batch 64 take days; the campaign's recipe is
``lab/scripts/campaign/distill_realtime_0.4.sh`` (batch 16, 8,000 steps). An interrupted run (Ctrl-C) exits 130 and
exports nothing.

CORPUS must be the corpus the teacher was trained on (the shipped weights: the procedural corpus of their model
card). ``--teacher DIR`` distils another pipeline folder (default: the shipped weights). ``--time`` needs no corpus:
it times one 196-frame motion at batch 1 with the teacher's sampler (its folder's solver, 50 steps, its guidance) and
with the student (``--student DIR``, else an untrained copy of the teacher's denoiser: the cost per step does not
depend on the weights) at 1, 2 and 4 steps, end to end and the denoising loop alone, all in one process.
"""
from __future__ import annotations

import argparse
import json
import logging
import statistics
import sys
import time


def build_parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0], formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--teacher", default=None, help="teacher pipeline folder (default: the shipped weights)")
    ap.add_argument("--data", default=None, help="the corpus (HumanML3D layout) the teacher was trained on")
    ap.add_argument("--out", default=None, help="run folder (log.jsonl, checkpoints, train state)")
    ap.add_argument("--steps", type=int, default=None, help="optimiser steps of the run (in total, across resumes)")
    ap.add_argument("--resume", action="store_true", help="continue the run in --out")
    ap.add_argument("--threads", type=int, default=1, help="torch threads (default 1)")
    ap.add_argument("--batch-size", type=int, default=None)
    ap.add_argument("--lr", type=float, default=None)
    ap.add_argument("--guidance", type=float, default=None, help="CFG weight of the teacher's ODE (default: its own)")
    ap.add_argument("--skip", type=int, default=None, help="timesteps of the teacher's DDIM step (default 20)")
    ap.add_argument("--ema-decay", type=float, default=None)
    ap.add_argument("--loss", choices=("huber", "l2"), default=None)
    ap.add_argument("--max-length", type=int, default=None, help="frames per training item (default 196)")
    ap.add_argument("--val-every", type=int, default=None)
    ap.add_argument("--ckpt-every", type=int, default=None)
    ap.add_argument("--seed", type=int, default=None)
    ap.add_argument("--export", default=None, help="write a weight folder of the run here")
    ap.add_argument("--export-model", choices=("student", "target"), default="student",
                    help="export the student (default) or its EMA target")
    ap.add_argument("--sample-steps", type=int, default=None, help="the exported folder's sampler steps (default 4)")
    ap.add_argument("--fp32", action="store_true", help="export float32 weights (default float16, as shipped)")
    ap.add_argument("--time", action="store_true", help="time the teacher and the student (no training)")
    ap.add_argument("--student", default=None, help="--time: an exported student folder (default: untrained copy)")
    ap.add_argument("--repeats", type=int, default=5, help="--time: timed calls per setting (median reported)")
    ap.add_argument("--prompt", default="a person walks forward and then turns around", help="--time: the prompt")
    return ap


def _overrides(args: argparse.Namespace) -> dict:
    pairs = {"batch_size": args.batch_size, "lr": args.lr, "guidance": args.guidance, "skip": args.skip,
             "ema_decay": args.ema_decay, "loss": args.loss, "max_length": args.max_length,
             "val_every": args.val_every, "ckpt_every": args.ckpt_every, "seed": args.seed}
    return {k: v for k, v in pairs.items() if v is not None}


def train(args: argparse.Namespace, text_encoder=None) -> bool:
    """Train (or continue) the run ``--out``; False when it was interrupted (Ctrl-C: a checkpoint is written)."""
    from salad_core.train.consistency import ConsistencyTrainConfig, train_consistency

    config = ConsistencyTrainConfig(teacher=args.teacher, max_steps=args.steps, num_threads=args.threads,
                                    **_overrides(args))
    res = train_consistency(args.data, args.out, config, text_encoder, resume=args.resume)
    print(json.dumps({"run": str(res.out_dir), "step": res.step, "last_loss": res.last_loss,
                      "best_val": res.best_val, "steps_per_s": round(res.steps_per_s, 4), "threads": res.threads,
                      "interrupted": bool(res.interrupted)}))
    return not res.interrupted


def export(args: argparse.Namespace, text_encoder=None) -> None:
    import torch

    from salad_core.train.consistency import DEFAULT_SAMPLE_STEPS, export_realtime

    out = export_realtime(args.out, args.export, teacher=args.teacher, which=args.export_model,
                          num_steps=args.sample_steps or DEFAULT_SAMPLE_STEPS, text_encoder=text_encoder,
                          dtype=None if args.fp32 else torch.float16)
    print(json.dumps({"exported": str(out), "pipeline": json.loads((out / "pipeline.json").read_text())}))


def _median_seconds(fn, repeats: int) -> float:
    fn()                                                    # warm-up (caches, allocator)
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return statistics.median(times)


def _loop_only(pipe, prompt: str, length: int, steps: int, solver: str, guidance):
    """A callable running :func:`salad_core.sampling.denoise` alone (text encoded, noise drawn once before)."""
    import torch

    from salad_core.sampling import denoise, make_scheduler

    text, null = pipe.encode_text([prompt])
    cond = pipe.denoiser.prepare_text(text.features, text.mask)
    uncond = pipe.denoiser.prepare_text(null.features, null.mask)
    n_lat = length // pipe.skeleton.unit_length
    noise = pipe.make_noise([0], n_lat)
    mask = pipe.frame_mask([length], n_lat)
    gen = [torch.Generator().manual_seed(1)]
    return lambda: denoise(pipe.denoiser, make_scheduler(pipe.diffusion, solver), cond, uncond, noise, mask,
                           guidance_scale=guidance, num_steps=steps, generator=gen if solver == "lcm" else None)


def time_sampling(args: argparse.Namespace, text_encoder=None) -> None:
    import copy

    import torch

    from salad_core.pipeline import SaladPipeline
    from salad_core.sampling import Guidance

    teacher = SaladPipeline.from_pretrained(args.teacher, text_encoder=text_encoder)
    if args.student is not None:
        student = SaladPipeline.from_pretrained(args.student, text_encoder=teacher.text_encoder)
        origin = args.student
    else:
        student = SaladPipeline(teacher.vae, copy.deepcopy(teacher.denoiser), teacher.text_encoder, teacher.mean,
                                teacher.std, diffusion=teacher.diffusion, solver="lcm", guidance=Guidance(1.0),
                                recovery=teacher.recovery, latent_stats=teacher.latent_stats, num_steps=4)
        origin = "untrained copy of the teacher's denoiser"
    length = teacher.skeleton.max_length
    rows = []
    settings = [("teacher", teacher, teacher.solver, 50, teacher.guidance)]
    settings += [("student", student, "lcm", s, Guidance(1.0)) for s in (1, 2, 4)]
    for name, pipe, solver, steps, guidance in settings:
        call = lambda: pipe(args.prompt, lengths=length, seed=0, solver=solver, num_steps=steps,  # noqa: E731
                            guidance_scale=guidance)
        total = _median_seconds(call, args.repeats)
        loop = _median_seconds(_loop_only(pipe, args.prompt, length, steps, solver, guidance), args.repeats)
        rows.append({"model": name, "solver": solver, "steps": steps, "guidance": guidance.describe(),
                     "forward_rows": 2 if guidance.cfg else 1, "call_s": round(total, 4), "loop_s": round(loop, 4),
                     "loop_per_step_ms": round(1000 * loop / steps, 2),
                     "outside_loop_s": round(total - loop, 4)})
    latents = teacher(args.prompt, lengths=length, seed=0).latents
    parts = {"encode_text_s": _median_seconds(lambda: teacher.encode_text([args.prompt]), args.repeats)}
    for method in ("fit", "positions"):        # decoding: the VAE, then the joints by each recovery method
        parts[f"decode_{method}_s"] = _median_seconds(lambda: teacher.decode(latents, [length], method), args.repeats)
    info = {"frames": length, "batch": 1, "torch_threads": torch.get_num_threads(), "repeats": args.repeats,
            "teacher": str(teacher.source), "student": origin, "prompt": args.prompt,
            "recovery": teacher.recovery, **{k: round(v, 4) for k, v in parts.items()}}
    print(json.dumps(info))
    for row in rows:
        print(json.dumps(row))


def main(argv: list[str] | None = None, *, text_encoder=None) -> int:
    args = build_parser().parse_args(argv)
    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(levelname)s %(name)s: %(message)s")
    import torch

    torch.set_num_threads(args.threads)
    if args.time:
        time_sampling(args, text_encoder)
        return 0
    if args.data is None and args.export is None:
        print("give --data CORPUS (train), --export DIR (export --out) or --time", file=sys.stderr)
        return 2
    if args.out is None:
        print("--out RUN is required to train or export", file=sys.stderr)
        return 2
    if args.data is not None and not train(args, text_encoder):
        print("interrupted: continue with --resume (nothing exported)", file=sys.stderr)
        return 130
    if args.export is not None:
        export(args, text_encoder)
    return 0


if __name__ == "__main__":
    from salad_core import openmp

    openmp.configure()
    sys.exit(main())
