#!/usr/bin/env python
"""Train the small ablation models (paper Tables 2-3, supplement Tables 2-4) and ship them.

Usage::

    python scripts/train_ablations.py --data CORPUS --work runs/ablations            # train + ship
    python scripts/train_ablations.py --data CORPUS --work runs/ablations --jobs 2   # two runs at a time
    python scripts/train_ablations.py --data CORPUS --work runs/ablations --only st pose full no_st
    python scripts/train_ablations.py --work runs/ablations --ship-only                # re-assemble

The recipe (variants, shared budgets) is ``configs/ablations.json``. Every run resumes, so an
interrupted study continues by running the same command again. The result goes to
``salad_core/weights/ablations/`` (fp16; loaded by :mod:`salad_core.ablations`).
"""
from __future__ import annotations

import argparse
import logging
import time
from pathlib import Path

from salad_core.ablations import load_recipe, plan_jobs, run_jobs, ship

REPO = Path(__file__).resolve().parents[1]


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--data", type=Path, help="corpus folder (HumanML3D layout); needed unless --ship-only")
    ap.add_argument("--work", required=True, type=Path, help="folder of the training runs")
    ap.add_argument("--recipe", type=Path, default=REPO / "configs" / "ablations.json")
    ap.add_argument("--jobs", type=int, default=1, help="runs trained at the same time (one torch thread each)")
    ap.add_argument("--only", nargs="+", default=None, help="variant names to train (default: all)")
    ap.add_argument("--ship", type=Path, default=REPO / "salad_core" / "weights" / "ablations",
                    help="where to assemble the shipped models")
    ap.add_argument("--ship-only", action="store_true", help="only assemble already trained runs")
    ap.add_argument("--no-ship", action="store_true", help="train only")
    args = ap.parse_args()
    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(levelname)s %(name)s: %(message)s")

    jobs = plan_jobs(load_recipe(args.recipe), args.work)
    if args.only:
        known = {j.variant.name for j in jobs}
        unknown = sorted(set(args.only) - known)
        if unknown:
            ap.error(f"--only: unknown variants {unknown}; the recipe has {sorted(known)}")
        jobs = [j for j in jobs if j.variant.name in args.only]
    if not args.ship_only:
        if args.data is None:
            ap.error("--data is required unless --ship-only")
        t0 = time.time()
        codes = run_jobs(jobs, args.data, max_parallel=args.jobs)
        print(f"trained {len(jobs)} runs in {(time.time() - t0) / 60:.1f} min: {codes}")
        if any(codes.values()):
            print("some runs failed (see their .log files in --work); not shipping")
            return 1
    if not args.no_ship:
        out = ship(jobs, args.ship)
        size = sum(p.stat().st_size for p in out.rglob("*") if p.is_file())
        print(f"shipped {len(jobs)} models to {out} ({size / 1e6:.1f} MB)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
