"""How to spend the machine's cores on training: one run alone, one run on two threads, or two runs side by side.

The ablation study trains two variants at once (``train_ablations.py --jobs 2``, one torch thread each) and the
long runs get ``--threads N``; which of the three settings gives the most training steps per second depends on
the machine (two vCPUs may share one physical core). This script measures it for one training step of a salad
model on random inputs shaped like a training batch (forward, backward, AdamW; no data loading):

* ``1 process x 1 thread``: one run alone;
* ``1 process x 2 threads``: one run with ``torch.set_num_threads(2)``;
* ``2 processes x 1 thread``: two runs side by side (``--jobs 2``).

Each setting trains for ``--seconds`` per round in fresh worker processes (started and warmed up before the
clock starts), the settings' order rotated every round, and the script prints the median steps per second of
each setting summed over its processes, and the ratio to one run alone. Run it on an otherwise idle machine
(stop or pause training runs: ``kill -STOP`` / ``-CONT``), or the figures measure the other load too.

Workloads (``--what``): ``vae`` (``lab/configs/v2_vae.json``, batch 64 x 40 frames: the ablation study's VAEs),
``denoiser`` (``lab/configs/v2_denoiser.json`` at the ablation study's small size, width 96, 3 layers, batch 32 x 30
latent frames), ``pst`` (KeyMotion's Parallel Skip Transformer, ``configs/keymotion-0.2.json``, batch 32).

Example::

    python bench/bench_parallel_jobs.py --what vae --seconds 20 --rounds 3
"""
from __future__ import annotations

import argparse
import json
import multiprocessing as mp
import os
import statistics
import time
from pathlib import Path

HERE = Path(__file__).resolve().parents[1]
#: setting name -> (processes, threads per process)
SETTINGS = {"1 process x 1 thread": (1, 1), "1 process x 2 threads": (1, 2), "2 processes x 1 thread": (2, 1)}
#: the ablation study's denoiser size (lab/configs/ablations_v2.json, "denoiser_model")
SMALL_DENOISER = {"width": 96, "heads": 4, "ff_dim": 384, "layers": 3}


def _make_step(what: str):
    """``(step, optimizer)``: a closure running one training step of ``what`` on fixed random inputs, and the
    AdamW it steps."""
    import torch

    from salad_core.io import config_from_dict

    torch.manual_seed(0)
    if what == "vae":
        from salad_core.models.vae import MotionVAE, VAEConfig
        from salad_core.train.vae_trainer import VAEObjective

        vae = MotionVAE(config_from_dict(VAEConfig, json.loads((HERE / "lab" / "configs" / "v2_vae.json").read_text())
                                         ["model"])).train()
        d = vae.feature_dim
        objective = VAEObjective(vae, stats=(torch.zeros(d), torch.ones(d)))
        params = vae.parameters()
        x = torch.randn(64, 40, d)
        eps = torch.randn(64, 40 // vae.downsample, 7, vae.config.latent_dim)
        eps2 = torch.randn_like(eps)
        loss_fn = lambda: objective(x, eps, eps2)["loss"]  # noqa: E731
    elif what == "denoiser":
        from salad_core.models.denoiser import Denoiser, DenoiserConfig

        doc = json.loads((HERE / "lab" / "configs" / "v2_denoiser.json").read_text())["model"]
        model = Denoiser(config_from_dict(DenoiserConfig, {**doc, **SMALL_DENOISER})).train()
        params = model.parameters()
        cfg = model.config
        x = torch.randn(32, 30, 7, cfg.latent_dim)
        t = torch.randint(0, 1000, (32,))
        text = torch.randn(32, 20, cfg.text_dim)
        mask = torch.ones(32, 20, dtype=torch.bool)
        loss_fn = lambda: model(x, t, text, mask).pow(2).mean()  # noqa: E731
    elif what == "pst":
        from salad_core.keymotion.pst import ParallelSkipTransformer, PSTConfig

        doc = json.loads((HERE / "configs" / "keymotion-0.2.json").read_text())["pst"]["model"]
        model = ParallelSkipTransformer(config_from_dict(PSTConfig, doc)).train()
        params = model.parameters()
        cfg = model.config
        x = torch.randn(32, cfg.latent_size, cfg.latent_dim)
        t = torch.randint(0, 1000, (32,))
        text = torch.randn(32, 20, cfg.text_dim)
        mask = torch.ones(32, 20, dtype=torch.bool)
        lengths = torch.randint(40, 197, (32,))
        loss_fn = lambda: model(x, t, text, mask, lengths=lengths).pow(2).mean()  # noqa: E731
    else:
        raise ValueError(f"what={what!r}: use 'vae', 'denoiser' or 'pst'")
    opt = torch.optim.AdamW(params, lr=1e-4)

    def step() -> None:
        opt.zero_grad(set_to_none=True)
        loss_fn().backward()
        opt.step()

    return step, opt


def _worker(what: str, threads: int, seconds: float, ready, go, result) -> None:
    """Build the model, warm up (2 steps), wait for ``go``, then count steps for ``seconds``."""
    import torch

    torch.set_num_threads(threads)
    step, _ = _make_step(what)
    step(), step()
    ready.release()
    go.wait()
    t0, n = time.perf_counter(), 0
    while time.perf_counter() - t0 < seconds:
        step()
        n += 1
    result.put(n / (time.perf_counter() - t0))


def measure(what: str, processes: int, threads: int, seconds: float) -> float:
    """Steps per second summed over ``processes`` workers of ``threads`` threads training side by side."""
    ctx = mp.get_context("spawn")
    ready, go, result = ctx.Semaphore(0), ctx.Event(), ctx.Queue()
    procs = [ctx.Process(target=_worker, args=(what, threads, seconds, ready, go, result)) for _ in range(processes)]
    for p in procs:
        p.start()
    for _ in procs:
        if not ready.acquire(timeout=600):
            raise RuntimeError("a worker did not start within 10 minutes")
    go.set()
    rates = [result.get(timeout=seconds + 600) for _ in procs]
    for p in procs:
        p.join()
        if p.exitcode != 0:
            raise RuntimeError(f"a worker failed (exit code {p.exitcode})")
    return float(sum(rates))


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--what", choices=("vae", "denoiser", "pst"), default="vae")
    p.add_argument("--seconds", type=float, default=20.0, help="timed seconds per setting and round")
    p.add_argument("--rounds", type=int, default=3)
    args = p.parse_args(argv)
    if args.seconds <= 0 or args.rounds < 1:
        p.error("--seconds must be > 0 and --rounds >= 1")
    names = list(SETTINGS)
    rates: dict[str, list[float]] = {n: [] for n in names}
    for r in range(args.rounds):
        for name in names[r % len(names):] + names[: r % len(names)]:     # rotate the order every round
            rates[name].append(measure(args.what, *SETTINGS[name], args.seconds))
    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")
    med = {n: statistics.median(v) for n, v in rates.items()}
    base = med[names[0]]
    print(f"{args.what} training step, {args.rounds} rounds of {args.seconds:.0f} s per setting, order rotated, "
          f"{os.cpu_count()} CPUs, load average at the end {load:.1f}")
    for n in names:
        procs = SETTINGS[n][0]
        print(f"  {n:<24} {med[n]:6.2f} steps/s in all ({med[n] / procs:5.2f} per process)  "
              f"{med[n] / base:5.2f}x  rounds: {', '.join(f'{v:.2f}' for v in rates[n])}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
