#!/usr/bin/env python
"""Train, evaluate and ship the ablation models (paper Tables 2-3, supplement Tables 2-4).

The staged study (issue 24, ``lab/configs/ablations_v2.json``, the default recipe) in one command::

    python lab/scripts/ablations/train_ablations.py --recipe lab/configs/ablations_v2.json --data CORPUS --work RUNS --jobs 2
    python lab/scripts/ablations/train_ablations.py --recipe lab/configs/ablations_v2.json --work RUNS --dry-run   # the plan
    python lab/scripts/ablations/train_ablations.py --recipe lab/configs/ablations_v2.json --data CORPUS --work RUNS --time 30
                                                        # CPU s/step of representative variants, for the plan

Every group of tables trains to its next stage (every variant of a table to exactly the same steps),
is evaluated there with one protocol (``RUNS/evaluations/<group>@<steps>.json``) and stops when the
orderings of its paper pairs are the same at two consecutive stages or its budget is spent; the VAE
groups come first and the denoisers learn on their final VAEs (packaged, fp16). A stopped group is also
kept in the repository (``lab/records/<recipe name>/``, ``--keep``), and so is a group in progress after each
new evaluation (its runs' fp16 weights at that stage): commit it, and on a new machine the same command
restores it and goes on from there (the group in progress warm-starts from its last evaluated stage).
``--keep-now`` keeps what ``--work`` holds at once, without training: a group in progress with each run at
its latest step, inside a stage too (pause the study first, and commit the keep folder before a working
session ends: a new machine then loses no trained step). Then the final stage's models (fp16),
the evaluations, ``index.json`` and ``MODEL_CARD.md`` go to ``--ship`` (default
``salad_core/weights/ablations``). Run the same command again after a kill: trained steps, snapshots
and evaluated rows are kept, the study continues where it stopped. Run it at low priority on a shared
machine (``nice -n 19``); each run uses one torch thread.

A recipe without ``groups`` (``lab/configs/ablations.json``, the 0.3 models) trains one fixed budget per
variant and ships without evaluating, as before::

    python lab/scripts/ablations/train_ablations.py --recipe lab/configs/ablations.json --data CORPUS --work RUNS --only st pose_long
    python lab/scripts/ablations/train_ablations.py --recipe lab/configs/ablations.json --work RUNS --ship-only
"""
from __future__ import annotations

import argparse
import json
import logging
import shlex
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))   # lab/: salad_lab

from salad_lab import (keep_study, load_recipe, load_staged_recipe, plan_jobs, run_jobs, run_study, ship,
                                  ship_study, study_plan)
from salad_lab.shipping import folder_size_mb
from salad_lab.runner import _alike
from salad_lab.stage_eval import load_evaluation
from salad_lab.timing import TIMING_FILE, time_variants

REPO = Path(__file__).resolve().parents[3]


def _hours(seconds: float | None) -> str:
    return "unmeasured" if seconds is None else f"{seconds / 3600:.1f} h"


def print_plan(recipe, work: Path | None, jobs: int) -> None:
    """The stages, the steps each variant trains in them, the CPU time the measured speeds give (``--time``'s
    ``WORK/timing.json`` if present, else the recipe's ``timing``) and which stages are already evaluated."""
    print(f"recipe {recipe.path}: stop rule {recipe.stop.consecutive} consecutive evaluations with equal orderings "
          f"({recipe.stop.compare}), else the last stage")
    timing = work / TIMING_FILE if work is not None else None
    speeds, note = recipe.steps_per_s, recipe.timing_note or "none"
    if timing is not None and timing.is_file():
        doc = json.loads(timing.read_text())
        speeds, note = doc["steps_per_cpu_s"], f"{timing}: {doc['measured']}"
    print(f"measured speeds (steps per CPU second): {note}: {dict(speeds)}")
    total = 0.0
    unmeasured = False
    for entry in study_plan(recipe, speeds):
        group = recipe.group(entry["group"])
        done = work is not None and load_evaluation(work, group, entry["steps"]) is not None
        sec = entry["cpu_seconds"]
        unmeasured |= sec is None
        total += sec or 0.0
        print(f"  {entry['stage']:>16s}: {len(entry['variants'])} {entry['kind']}s x {entry['new_steps_per_variant']:,} "
              f"new steps ({', '.join(entry['tables'])}), CPU {_hours(sec)}{'  [evaluated]' if done else ''}")
    print(f"all stages, training only: {_hours(total)} of CPU time"
          + (" (some variants unmeasured: not counted)" if unmeasured else "")
          + f"; about {_hours(total / max(1, jobs))} of wall time with --jobs {jobs} on free cores. "
            "Evaluation time comes on top; a group that stops early skips its later stages.")


def staged_main(args, ap) -> int:
    recipe = load_staged_recipe(args.recipe)
    if args.time:
        if args.data is None:
            ap.error("--time needs --data (a corpus to train the timing runs on)")
        # one variant per kind of cost (VAE latent kind; denoiser's VAE): the plan takes the others alike
        names = args.time_variants or list({_alike(recipe, v): v for g in reversed(recipe.groups)
                                            for v in reversed(g.variants)}.values())
        result = time_variants(recipe, names, args.data, args.work, steps=args.time)
        print(json.dumps(result, indent=2))
        return 0
    if args.dry_run:
        print_plan(recipe, args.work, args.jobs)
        return 0
    if args.keep_now:
        if args.no_keep:
            ap.error("--keep-now and --no-keep contradict each other")
        keep = args.keep or REPO / "lab" / "records" / Path(recipe.path).stem
        for name, what in keep_study(recipe, args.work, keep).items():
            print(f"  {name}: {what}")
        print(f"kept in {keep}")
        return 0
    if args.data is None:
        ap.error("--data is required (the corpus the study trains on and evaluates on)")
    command = " ".join(["python lab/scripts/ablations/train_ablations.py", "--recipe", _rel(args.recipe), "--data", "CORPUS",
                        "--work", "RUNS", *(["--jobs", str(args.jobs)] if args.jobs != 1 else [])])
    t0 = time.time()
    keep = None if args.no_keep else (args.keep or REPO / "lab" / "records" / Path(recipe.path).stem)
    outcomes = run_study(recipe, args.data, args.work, max_parallel=args.jobs, groups=args.groups, keep=keep)
    print(f"study done in {(time.time() - t0) / 60:.1f} min")
    for name, o in outcomes.items():
        agree = [k for k, v in o.evaluations[-1]["orderings"].items() if v["agrees"]]
        print(f"  {name}: stopped at {o.decision.steps:,} steps ({o.decision.reason}); "
              f"{len(agree)} of {len(o.evaluations[-1]['orderings'])} orderings agree with the paper")
    if args.no_ship or args.groups:
        print("not shipping" + (" (--groups trains part of the study)" if args.groups else ""))
        return 0
    from salad_lab.probes import load_probes

    probes = load_probes(keep / "probes.json") if keep is not None else {}
    out = ship_study(recipe, outcomes, args.ship, args.work, command=command, data=str(args.data), probes=probes)
    print(f"shipped to {out} ({folder_size_mb(out):.1f} MB) with {out / 'MODEL_CARD.md'}")
    return 0


def _rel(path: Path) -> str:
    try:
        return str(Path(path).resolve().relative_to(REPO))
    except ValueError:
        return str(path)


def legacy_main(args, ap) -> int:
    jobs = plan_jobs(load_recipe(args.recipe), args.work)
    if args.only:
        known = {j.variant.name for j in jobs}
        unknown = sorted(set(args.only) - known)
        if unknown:
            ap.error(f"--only: unknown variants {unknown}; the recipe has {sorted(known)}")
        jobs = [j for j in jobs if j.variant.name in args.only]
    if args.dry_run:
        for j in jobs:
            print(f"  {j.run_dir.name}: {j.config['train'].get('max_steps')} steps")
        return 0
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
        print(f"shipped {len(jobs)} models to {out} ({folder_size_mb(out):.1f} MB)")
    return 0


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--data", type=Path, help="corpus folder (HumanML3D layout); needed to train")
    ap.add_argument("--work", required=True, type=Path, help="folder of the training runs, snapshots and evaluations")
    ap.add_argument("--recipe", type=Path, default=REPO / "lab" / "configs" / "ablations_v2.json")
    ap.add_argument("--jobs", type=int, default=1, help="runs trained at the same time (one torch thread each)")
    ap.add_argument("--ship", type=Path, default=REPO / "salad_core" / "weights" / "ablations",
                    help="where to assemble the shipped models")
    ap.add_argument("--no-ship", action="store_true", help="train (and evaluate) only")
    ap.add_argument("--dry-run", action="store_true", help="print the plan and exit")
    ap.add_argument("--time", type=int, default=0, metavar="STEPS",
                    help="staged recipes: train STEPS steps of representative variants in this process and write "
                         "their CPU seconds per step to WORK/timing.json (read by --dry-run), then exit")
    ap.add_argument("--time-variants", nargs="+", default=None,
                    help="with --time: the variants to time (default: one per kind of cost: each VAE latent kind, "
                         "denoisers on each VAE)")
    ap.add_argument("--groups", nargs="+", default=None,
                    help="staged recipes: only these groups (their VAE groups must have stopped); does not ship")
    ap.add_argument("--keep", type=Path, default=None,
                    help="staged recipes: where stopped groups and the progress of a running one are kept, and "
                         "restored from when --work lacks them (default: lab/records/<recipe name>/ in the repository; "
                         "commit it, so that a new machine goes on from there)")
    ap.add_argument("--no-keep", action="store_true", help="staged recipes: neither keep nor restore groups")
    ap.add_argument("--keep-now", action="store_true",
                    help="staged recipes: keep what --work holds (stopped groups; a running group's runs at their "
                         "latest steps and its stages trained but not evaluated) and exit, without training; run it "
                         "(with the study paused) before a working session ends and commit the keep folder")
    ap.add_argument("--only", nargs="+", default=None, help="recipes without groups: variant names to train")
    ap.add_argument("--ship-only", action="store_true", help="recipes without groups: only assemble trained runs")
    args = ap.parse_args(argv)
    if args.jobs < 1:
        ap.error(f"--jobs {args.jobs}: use an integer >= 1")
    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(levelname)s %(name)s: %(message)s")
    staged = "groups" in json.loads(args.recipe.read_text())
    if staged and (args.only or args.ship_only):
        ap.error("--only and --ship-only are for recipes without groups; a staged study trains whole groups "
                 "(--groups) and ships when every group has stopped")
    if not staged and args.groups:
        ap.error(f"--groups needs a staged recipe; {args.recipe} has no 'groups'")
    return staged_main(args, ap) if staged else legacy_main(args, ap)


if __name__ == "__main__":
    sys.exit(main())
