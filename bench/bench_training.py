"""Old vs new trainer, side by side: steps/s, samples x frames/s and the loss curves (issue 19).

Trains the same model with the same config on the same corpus twice, at the same time: once with
the code of an older checkout (``--old``, e.g. ``git worktree add /tmp/h3_old bb0d404``) and once
with this checkout, each in its own process with the same torch threads. Running both at once means
both meet the same machine (other jobs, speed swings), so their ratio is fair on a busy machine;
on an otherwise idle 2-core machine each gets one core. The new side's latent cache is built first
(timed separately) in a shared folder, so the timed run starts from step 1 for both.

Prints, for each side, optimiser steps/s and valid motion frames/s (both without start-up,
validation and checkpoints: the trainers' own ``TrainResult`` time base), their ratio, and the
loss curves as means over windows of ``--window`` steps side by side with the standard error of
each window, so "equal within noise" can be read off.

Example::

    python bench/bench_training.py --old /tmp/h3_old --data /tmp/h3_corpus --what denoiser --steps 300
    python bench/bench_training.py --old /tmp/h3_old --data /tmp/h3_corpus --what vae --steps 200
    python bench/bench_training.py --old /tmp/f_old --data /tmp/h3_corpus --what vae --steps 200 \
        --config lab/configs/v2_vae.json --new-train autocast=bf16   # a field for the new side only
    python bench/bench_training.py --threads-ab --data /tmp/h3_corpus --what vae   # 1 vs 2 threads, this checkout

``--threads-ab`` alternates 1 and 2 torch threads in one process of this checkout's trainer (rounds of a
few steps, the order flipped every round) and prints the medians and the load average during the rounds.
"""
from __future__ import annotations

import argparse
import json
import math
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parents[1]

# Runs inside each side's process, with that side's checkout first on sys.path. It only uses
# APIs both versions have; the new side additionally gets the shared latent cache folder.
RUNNER = r'''
import json, sys, time, torch
spec = json.loads(sys.argv[1])
sys.path.insert(0, spec["root"])
torch.set_num_threads(spec["threads"])
import dataclasses, inspect
from salad_core.io import config_from_dict
from salad_core.train.common import fit
from salad_core.train.distributed import DistEnv
doc = spec["config"]
env = DistEnv()
if spec["what"] == "denoiser":
    from salad_core.models.denoiser import DenoiserConfig
    from salad_core.train.config import DenoiserTrainConfig as TC
    from salad_core.train.denoiser_trainer import build_denoiser_task as build
elif spec["what"] == "vae":
    from salad_core.models.vae import VAEConfig
    from salad_core.train.config import VAETrainConfig as TC
    from salad_core.train.vae_trainer import build_vae_task as build
else:
    from salad_core.keymotion import train as km
    TC = km.KeyMotionTrainConfig
    build = km.build_pst_task if spec["what"] == "pst" else km.build_mmae_task
known = {f.name for f in dataclasses.fields(TC)}
if spec["what"] in ("pst", "mmae"):
    for section in [doc] + [doc[s] for s in ("kf_vae", "pst", "mmae") if s in doc]:
        if "train" in section:
            section["train"] = {k: v for k, v in section["train"].items() if k in known}
    recipe = km.KeyMotionRecipe.from_doc(doc)
    train = {f.name: getattr(getattr(recipe, spec["what"] + "_train"), f.name) for f in dataclasses.fields(TC)}
else:
    train = {k: v for k, v in doc["train"].items() if k in known}
train.update(max_steps=spec["steps"], log_every=spec["log_every"], progress=False, num_threads=spec["threads"],
             ckpt_every=0, val_every=0, **({"seed": spec["seed"]} if spec.get("seed") is not None else {}))
tc = TC(**train) if spec["what"] in ("pst", "mmae") else config_from_dict(TC, train)
t0 = time.perf_counter()
if spec["what"] in ("pst", "mmae"):
    model = getattr(recipe, spec["what"] + "_model")
    kw = {"cache_dir": spec["cache_dir"]} if "cache_dir" in inspect.signature(build).parameters else {}
    if spec["what"] == "pst":
        task = build(spec["data"], spec["kf_vae"], model, tc, env, **kw)
    else:
        task = build(spec["data"], model, tc, env, "minilm", 20)
elif spec["what"] == "denoiser":
    mc = config_from_dict(DenoiserConfig, doc["model"])
    kw = {"cache_dir": spec["cache_dir"]} if "cache_dir" in inspect.signature(build).parameters else {}
    task = build(spec["data"], spec["vae"], mc, tc, env, **kw)
else:
    task = build(spec["data"], config_from_dict(VAEConfig, doc["model"]), tc, env)
built = time.perf_counter() - t0
frames = [0]
collate = task.collate
def counting(items):
    batch = collate(items)
    frames[0] += int(batch["length"].sum()) if "length" in batch else int(batch["motion"].shape[0] * batch["motion"].shape[1])
    return batch
task.collate = counting
stamps = []
t_fit = time.time()
res = fit(task, spec["out"], tc, env=env, on_step=lambda s: stamps.append(time.time()))
print("RESULT " + json.dumps({"steps": res.step, "steps_per_s": res.steps_per_s, "frames": frames[0],
                              "build_s": built, "t_fit": t_fit, "stamps": stamps,
                              "version": __import__("salad_core").__file__}), flush=True)
'''


def _config_path(args: argparse.Namespace) -> Path:
    """``--config`` or the default config of ``--what`` (``lab/configs/default_<what>.json``)."""
    name = "keymotion" if args.what in ("pst", "mmae") else args.what
    return args.config if args.config is not None else HERE / "lab" / "configs" / f"default_{name}.json"


def _train_overrides(pairs: list[str]) -> dict:
    """``KEY=VALUE`` strings (VALUE read as JSON when it parses, else as a string) -> dict."""
    from salad_core.train.config import parse_overrides

    try:
        return parse_overrides(pairs)
    except ValueError as e:
        raise SystemExit(f"--new-train: {e}") from None


def _spec(root: Path, args: argparse.Namespace, out: Path, steps: int, cache_dir: Path | None,
          overrides: dict | None = None) -> dict:
    config = json.loads(_config_path(args).read_text())
    if overrides:
        config["train"] = {**config.get("train", {}), **overrides}
    return {"root": str(root), "what": args.what, "data": str(args.data), "vae": str(args.vae), "config": config,
            "kf_vae": str(HERE / "salad_core" / "weights" / "keymotion" / "kf_vae"),
            "steps": steps, "log_every": args.log_every, "threads": args.threads, "out": str(out),
            "cache_dir": str(cache_dir) if cache_dir else None, "seed": args.seed}


def _launch(spec: dict, log_path: Path) -> subprocess.Popen:
    env = {**os.environ, "OMP_NUM_THREADS": str(spec["threads"]), "PYTHONPATH": spec["root"]}
    fh = open(log_path, "w")
    return subprocess.Popen([sys.executable, "-c", RUNNER, json.dumps(spec)], stdout=fh, stderr=subprocess.STDOUT,
                            env=env, cwd=spec["root"])


def _result(log_path: Path) -> dict:
    for line in log_path.read_text().splitlines():
        if line.startswith("RESULT "):
            return json.loads(line[len("RESULT "):])
    raise RuntimeError(f"no result in {log_path}:\n{log_path.read_text()[-3000:]}")


def _losses(run: Path) -> list[tuple[int, float]]:
    out = []
    for line in (run / "log.jsonl").read_text().splitlines():
        rec = json.loads(line)
        if "loss" in rec:
            out.append((int(rec["step"]), float(rec["loss"])))
    return out


def _windows(points: list[tuple[int, float]], window: int) -> dict[int, tuple[float, float, int]]:
    groups: dict[int, list[float]] = {}
    for step, loss in points:
        groups.setdefault((step - 1) // window, []).append(loss)
    out = {}
    for w, vals in groups.items():
        m = sum(vals) / len(vals)
        sd = math.sqrt(sum((v - m) ** 2 for v in vals) / (len(vals) - 1)) if len(vals) > 1 else float("nan")
        out[w] = (m, sd / math.sqrt(len(vals)), len(vals))
    return out


THREADS_RUNNER = r'''
import json, os, sys, time, statistics, torch
spec = json.loads(sys.argv[1])
from salad_core.io import config_from_dict
from salad_core.train.distributed import DistEnv
from salad_core.train.profile import StepRunner
doc = spec["config"]
if spec["what"] == "denoiser":
    from salad_core.models.denoiser import DenoiserConfig
    from salad_core.train.config import DenoiserTrainConfig as TC
    from salad_core.train.denoiser_trainer import build_denoiser_task
    tc = config_from_dict(TC, {**doc["train"], "progress": False})
    mc = config_from_dict(DenoiserConfig, doc["model"])
    build = lambda c: build_denoiser_task(spec["data"], spec["vae"], mc, c, DistEnv(), cache_dir=spec["cache_dir"])
else:
    from salad_core.models.vae import VAEConfig
    from salad_core.train.config import VAETrainConfig as TC
    from salad_core.train.vae_trainer import build_vae_task
    tc = config_from_dict(TC, {**doc["train"], "progress": False})
    mc = config_from_dict(VAEConfig, doc["model"])
    build = lambda c: build_vae_task(spec["data"], mc, c, DistEnv())
runner = StepRunner("ab", build, tc)
times = {1: [], 2: []}
loads = []
for r in range(spec["rounds"]):
    for n in ((1, 2) if r % 2 == 0 else (2, 1)):
        torch.set_num_threads(n)
        runner.step(record=False)                     # settle the thread pool
        t0 = time.perf_counter()
        for _ in range(spec["steps"]):
            runner.step(record=False)
        times[n].append((time.perf_counter() - t0) / spec["steps"])
        loads.append(os.getloadavg()[0])
print("RESULT " + json.dumps({"times": times, "loads": loads}), flush=True)
'''


def threads_ab(args: argparse.Namespace, out: Path) -> int:
    """1 vs 2 torch threads for this checkout's trainer alone, alternating in one process (medians)."""
    import statistics

    config = json.loads(_config_path(args).read_text())
    config["train"] = {**config["train"], **_train_overrides(args.new_train)}
    spec = {"what": args.what, "data": str(args.data), "vae": str(args.vae), "config": config,
            "cache_dir": str(out / "latent_cache"), "rounds": args.rounds, "steps": args.ab_steps}
    env = {**os.environ, "PYTHONPATH": str(HERE)}
    env.pop("OMP_NUM_THREADS", None)
    proc = subprocess.run([sys.executable, "-c", THREADS_RUNNER, json.dumps(spec)], capture_output=True, text=True,
                          env=env, cwd=HERE)
    lines = [l for l in proc.stdout.splitlines() if l.startswith("RESULT ")]
    if proc.returncode or not lines:
        raise RuntimeError(proc.stdout[-2000:] + proc.stderr[-3000:])
    res = json.loads(lines[0][len("RESULT "):])
    t1, t2 = (statistics.median(res["times"][k]) for k in ("1", "2"))
    print(f"{args.what} step, 1 vs 2 torch threads, {args.rounds} alternating rounds of {args.ab_steps} steps "
          f"(one process; load average during the rounds {min(res['loads']):.2f}-{max(res['loads']):.2f}):")
    print(f"  1 thread : median {t1 * 1e3:.0f} ms/step  (rounds: {', '.join(f'{t * 1e3:.0f}' for t in res['times']['1'])})")
    print(f"  2 threads: median {t2 * 1e3:.0f} ms/step  (rounds: {', '.join(f'{t * 1e3:.0f}' for t in res['times']['2'])})")
    print(f"  speed-up of 2 threads: {t1 / t2:.2f}x")
    return 0


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--old", type=Path, help="checkout of the older release (git worktree)")
    p.add_argument("--data", required=True, type=Path, help="HumanML3D-layout corpus")
    p.add_argument("--what", choices=("denoiser", "vae", "pst", "mmae"), default="denoiser",
                   help="the model trained (pst, mmae: KeyMotion's stages; the PST on the shipped keyframe VAE)")
    p.add_argument("--vae", type=Path, default=HERE / "salad_core" / "weights" / "salad" / "vae",
                   help="frozen VAE of the denoiser runs (default: the shipped one)")
    p.add_argument("--config", type=Path, default=None,
                   help="config JSON of both sides (default: lab/configs/default_<what>.json)")
    p.add_argument("--new-train", action="append", default=[], metavar="KEY=VALUE",
                   help="a training-config field for the new side only (repeatable), e.g. autocast=bf16")
    p.add_argument("--steps", type=int, default=300)
    p.add_argument("--threads", type=int, default=1)
    p.add_argument("--seed", type=int, default=None, help="training seed of both sides (default: the config's)")
    p.add_argument("--log-every", type=int, default=10)
    p.add_argument("--window", type=int, default=50, help="steps per window of the loss-curve table")
    p.add_argument("--out", type=Path, default=None, help="folder for the runs (default: a temporary one)")
    p.add_argument("--threads-ab", action="store_true",
                   help="instead: 1 vs 2 torch threads for this checkout's trainer alone (no --old needed)")
    p.add_argument("--rounds", type=int, default=6, help="--threads-ab: alternating rounds")
    p.add_argument("--ab-steps", type=int, default=3, help="--threads-ab: timed steps per round and setting")
    args = p.parse_args(argv)
    out = args.out or Path(tempfile.mkdtemp(prefix="bench_training_"))
    out.mkdir(parents=True, exist_ok=True)
    if args.threads_ab:
        return threads_ab(args, out)
    if args.old is None:
        p.error("--old is required (except with --threads-ab)")
    cache = out / "latent_cache" if args.what in ("denoiser", "pst") else None
    if cache is not None:
        t0 = time.perf_counter()
        pre = _launch(_spec(HERE, args, out / "prebuild", 0, cache), out / "prebuild.log")
        if pre.wait():
            raise RuntimeError((out / "prebuild.log").read_text()[-3000:])
        print(f"latent cache prebuilt in {time.perf_counter() - t0:.0f} s (data loading and text features included; "
              f"{_result(out / 'prebuild.log')['build_s']:.0f} s task build)")
    load0 = os.getloadavg()[0]
    overrides = _train_overrides(args.new_train)
    procs = {name: _launch(_spec(root, args, out / name, args.steps, cache if name == "new" else None,
                                 overrides if name == "new" else None),
                           out / f"{name}.log") for name, root in (("old", args.old.resolve()), ("new", HERE))}
    codes = {name: proc.wait() for name, proc in procs.items()}
    load1 = os.getloadavg()[0]
    for name, code in codes.items():
        if code:
            raise RuntimeError(f"{name} failed:\n{(out / f'{name}.log').read_text()[-3000:]}")
    res = {name: _result(out / f"{name}.log") for name in procs}
    print(f"{args.what} ({_config_path(args).name}"
          + (f"; new side: {', '.join(args.new_train)}" if args.new_train else "") + "), "
          f"{args.steps} steps each, both processes at once, {args.threads} torch thread(s) each; "
          f"load average {load0:.2f} at the start, {load1:.2f} at the end; runs in {out}")
    print(f"{'':8s} {'steps/s':>9s} {'frames/s':>10s} {'frames/step':>12s}  code")
    for name, r in res.items():
        fps = r["frames"] / r["steps"] * r["steps_per_s"] if r["steps"] else float("nan")
        r["frames_per_s"] = fps
        print(f"{name:8s} {r['steps_per_s']:9.3f} {fps:10.0f} {r['frames'] / max(r['steps'], 1):12.0f}  {r['version']}")
    print(f"ratio new/old: steps/s {res['new']['steps_per_s'] / res['old']['steps_per_s']:.2f}, "
          f"samples x frames/s {res['new']['frames_per_s'] / res['old']['frames_per_s']:.2f}")
    # the side that finishes first leaves the other a quieter machine: also compare the rates over the
    # wall-clock span in which both were training (step completion times)
    lo = max(r["stamps"][0] for r in res.values() if r["stamps"])
    hi = min(r["stamps"][-1] for r in res.values() if r["stamps"])
    rates = {name: sum(lo < t <= hi for t in r["stamps"]) / (hi - lo) for name, r in res.items()} if hi > lo else {}
    if rates and min(rates.values()) > 0:
        print(f"while both were training ({hi - lo:.0f} s): steps/s old {rates['old']:.4f}, new {rates['new']:.4f}, "
              f"ratio {rates['new'] / rates['old']:.2f}; samples x frames/s ratio (mean frames per step) "
              f"{rates['new'] * res['new']['frames'] / (rates['old'] * res['old']['frames']):.2f}")
    curves = {name: _windows(_losses(out / name), args.window) for name in procs}
    print(f"\nloss, mean over windows of {args.window} steps (+- standard error of the logged values, "
          f"one per {args.log_every} steps)")
    print(f"{'steps':>11s} {'old':>20s} {'new':>20s} {'diff/se':>8s}")
    for w in sorted(set(curves["old"]) & set(curves["new"])):
        (mo, so, _), (mn, sn, _) = curves["old"][w], curves["new"][w]
        z = (mn - mo) / math.sqrt(so ** 2 + sn ** 2) if so == so and sn == sn and (so or sn) else float("nan")
        print(f"{w * args.window + 1:5d}-{(w + 1) * args.window:<5d} {mo:12.4f} +- {so:.4f} {mn:12.4f} +- {sn:.4f} {z:8.2f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
