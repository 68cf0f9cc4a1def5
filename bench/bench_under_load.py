"""Batch-1 sampling speed of the paper configuration with and without a competing CPU-bound process,
this tree side by side with another checkout (issue 19, "Sampling").

Each measurement is a fresh child process (the OpenMP runtime reads its settings once, at start-up)
that builds the paper's denoiser (width 256, 8 heads, 5 layers, CLIP-sized 512-d text padded to 77
tokens, random weights with seed 0), warms up with one step and times guided DDIM steps at batch 1,
196 frames (49 latent frames), w 7.5. "loaded" runs one busy-looping Python process beside the
child for the whole measurement, at the same niceness. Trees and scenarios are interleaved round by
round so that slow phases of a shared machine hit every variant alike; the table gives the median
step (ms) over all steps of all rounds, the mean step (the tail matters under load), and the ratio
of this tree to the other one.

Usage::

    git worktree add /tmp/old_release bb0d404          # the release to compare against
    python bench/bench_under_load.py --other /tmp/old_release [--rounds 3] [--steps 20] [--threads 2]
    python bench/bench_under_load.py --other /tmp/old_release --env OMP_WAIT_POLICY=PASSIVE --env GOMP_SPINCOUNT=10000

``--env`` adds variants of this tree run with extra environment variables (to compare OpenMP
settings). ``--nice N`` runs children and competitor at niceness N (e.g. -10 as root, so that
other low-priority work on a shared machine does not disturb the comparison).
"""
from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parents[1]

#: The child: imports salad_core from the tree on sys.path[0], prints per-step seconds as JSON.
CHILD = r"""
import json, sys, time
sys.path.insert(0, sys.argv[1])
import salad_core                       # first: salad's start-up settings apply before torch loads
import torch
threads, steps = int(sys.argv[2]), int(sys.argv[3])
torch.set_num_threads(threads)
from salad_core.models.denoiser import Denoiser, DenoiserConfig
from salad_core.sampling import denoise, make_scheduler
torch.manual_seed(0)
cfg = DenoiserConfig()
model = Denoiser(cfg).eval()
g = torch.Generator().manual_seed(0)
text = torch.randn(1, 77, cfg.text_dim, generator=g)
mask = torch.arange(77)[None] < 16
null_mask = torch.zeros(1, 77, dtype=torch.bool); null_mask[0, :2] = True
null = (torch.randn(1, 77, cfg.text_dim, generator=g), null_mask)
noise = torch.randn(1, 49, cfg.num_parts, cfg.latent_dim, generator=g)
fm = torch.ones(1, 49, dtype=torch.bool)
denoise(model, make_scheduler(), (text, mask), null, noise, fm, guidance_scale=7.5, num_steps=1)
stamps = [time.perf_counter()]
denoise(model, make_scheduler(), (text, mask), null, noise, fm, guidance_scale=7.5, num_steps=steps,
        callback=lambda info, z: stamps.append(time.perf_counter()))
print(json.dumps({"steps": [b - a for a, b in zip(stamps, stamps[1:])],
                  "salad": getattr(salad_core, "__version__", "?"), "torch": torch.__version__}))
"""

#: Environment variables that steer the OpenMP runtime: removed from the children's environment
#: unless a variant sets them, so every variant starts from the same defaults.
OMP_VARS = ("OMP_WAIT_POLICY", "GOMP_SPINCOUNT", "OMP_NUM_THREADS", "SALAD_OMP_WAIT")


def _child_env(extra: dict[str, str]) -> dict[str, str]:
    env = {k: v for k, v in os.environ.items() if k not in OMP_VARS}
    env.update(extra)
    return env


def run_child(tree: Path, threads: int, steps: int, env: dict[str, str], nice: int) -> dict:
    """Run one timing child; returns its JSON (``steps``: seconds per step)."""
    cmd = [sys.executable, "-c", CHILD, str(tree), str(threads), str(steps)]
    if nice:
        cmd = ["nice", "-n", str(nice), *cmd]
    out = subprocess.run(cmd, env=_child_env(env), capture_output=True, text=True, check=False)
    if out.returncode != 0:
        raise RuntimeError(f"timing child failed for {tree} ({env}):\n{out.stderr[-2000:]}")
    return json.loads(out.stdout.strip().splitlines()[-1])


def start_competitor(nice: int) -> subprocess.Popen:
    """One CPU-bound process (a Python busy loop) at niceness ``nice``."""
    cmd = [sys.executable, "-c", "while True: pass"]
    if nice:
        cmd = ["nice", "-n", str(nice), *cmd]
    return subprocess.Popen(cmd)


def measure(variants: list[tuple[str, Path, dict[str, str]]], *, rounds: int, steps: int, threads: int,
            nice: int) -> dict[tuple[str, str], list[float]]:
    """Per (variant, scenario) all step times (s) over ``rounds`` interleaved rounds."""
    times: dict[tuple[str, str], list[float]] = {}
    for r in range(rounds):
        for scenario in ("quiet", "loaded"):
            comp = start_competitor(nice) if scenario == "loaded" else None
            try:
                if comp is not None:
                    time.sleep(0.5)
                order = variants if r % 2 == 0 else variants[::-1]
                for name, tree, env in order:
                    res = run_child(tree, threads, steps, env, nice)
                    times.setdefault((name, scenario), []).extend(res["steps"])
                    print(f"round {r + 1} {scenario:6s} {name:28s} median "
                          f"{statistics.median(res['steps']) * 1e3:7.1f} ms  mean "
                          f"{statistics.fmean(res['steps']) * 1e3:7.1f} ms", flush=True)
            finally:
                if comp is not None:
                    comp.kill()
                    comp.wait()
    return times


def format_table(times: dict[tuple[str, str], list[float]], reference: str) -> str:
    """Markdown table: median and mean step per variant and scenario, ratios to ``reference``."""
    lines = ["| variant | scenario | median step (ms) | mean step (ms) | median vs other | mean vs other |",
             "|---|---|---|---|---|---|"]
    for (name, scenario), ts in times.items():
        ref = times.get((reference, scenario))
        med, mean = statistics.median(ts), statistics.fmean(ts)
        rmed = f"{med / statistics.median(ref):.2f}" if ref else ""
        rmean = f"{mean / statistics.fmean(ref):.2f}" if ref else ""
        lines.append(f"| {name} | {scenario} | {med * 1e3:.1f} | {mean * 1e3:.1f} | {rmed} | {rmean} |")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--other", required=True, help="another checkout of salad (e.g. a worktree of the release)")
    p.add_argument("--rounds", type=int, default=3, help="interleaved rounds (default 3)")
    p.add_argument("--steps", type=int, default=20, help="timed DDIM steps per child (default 20)")
    p.add_argument("--threads", type=int, default=2, help="torch threads of the children (default 2)")
    p.add_argument("--nice", type=int, default=0, help="niceness of children and competitor (default 0)")
    p.add_argument("--env", action="append", default=[], metavar="VAR=VALUE",
                   help="an extra variant of this tree with this environment (repeatable)")
    args = p.parse_args(argv)
    other = Path(args.other).resolve()
    if not (other / "salad_core" / "__init__.py").is_file():
        p.error(f"--other {other} is not a salad checkout (no salad_core/__init__.py)")
    variants = [("other", other, {}), ("this", HERE, {})]
    for item in args.env:
        key, sep, value = item.partition("=")
        if not sep or not key:
            p.error(f"--env takes VAR=VALUE, got {item!r}")
        variants.append((f"this {item}", HERE, {key: value}))
    start = time.time()
    times = measure(variants, rounds=args.rounds, steps=args.steps, threads=args.threads, nice=args.nice)
    print()
    print(f"paper configuration, batch 1, 196 frames, DDIM, w 7.5, {args.threads} torch threads, "
          f"{args.rounds} rounds x {args.steps} steps, nice {args.nice}, {time.time() - start:.0f} s, "
          f"load at end {os.getloadavg()[0]:.2f}")
    print(format_table(times, "other"))
    return 0


if __name__ == "__main__":
    sys.exit(main())
