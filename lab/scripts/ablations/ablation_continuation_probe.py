#!/usr/bin/env python
"""Continue ablation denoisers past the study's last stage with another schedule, and score them with that stage's
protocol (issue 24).

The staged study trains every denoiser at a constant learning rate (by design: a stage can be continued), so a gap
between two rows may be the constant rate's: each row's figures move between stages by about as much as some gaps.
This probe copies the study's runs at their last stage (weights, optimiser, data order), continues them with a
changed schedule, typically a decaying learning rate, and scores them side by side with the stage's protocol (the
same crops, captions and noise), so a pair's paired gap after the continuation reads against its gap at the stage::

    # 1. copy the runs, write their configs (the study's with --set) and print the train commands
    python lab/scripts/ablations/ablation_continuation_probe.py prepare --study-work ~/salad-runs/ablations_v3 \\
        --variants full x0 --set train.max_steps=10000 "train.milestones=[7500,8500]" \\
        --out-dir ~/salad-runs/abl_probe/decay
    # 2. after training: score them and record the pair
    python lab/scripts/ablations/ablation_continuation_probe.py score \\
        --stage-eval salad_core/weights/ablations/evaluations/denoisers@8000.json --out-dir ~/salad-runs/abl_probe/decay \\
        --variants full x0 --name lr_decay --change-text "learning rate x0.2 at 8,000 and 9,000 steps" \\
        --data CORPUS_2.4 \\
        --out lab/records/ablations_v2/continuation_probe.json

The study's runs must still hold their train state at the stage (``<work>/den_<variant>``, as the study leaves
them); on a new machine the study is trained to that stage first (``lab/scripts/ablations/train_ablations.py``). The record keeps
the commands and the configs' changes.
"""
from __future__ import annotations

import argparse
import json
import shlex
import shutil
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[3]
sys.path.insert(0, str(REPO))
sys.path.insert(0, str(REPO / "lab"))   # salad_lab
sys.path.insert(0, str(Path(__file__).resolve().parent))   # sibling scripts
from ablation_vae_probe import apply_sets, parse_sets  # noqa: E402  (the VAE probe's --set handling, shared)


def prepare(work: Path, variants: list[str], sets: dict, out_dir: Path) -> list[str]:
    """Copy ``work/den_<v>`` to ``out_dir/den_<v>`` (unless already there: a continuation in progress is kept) and
    write ``out_dir/den_<v>.json`` (the study's config with ``sets``); return the train commands.

    A variant written ``NAME=RUN`` is a denoiser probe (``lab/scripts/ablations/ablation_denoiser_probe.py``) instead: its run
    ``RUN`` and the config beside it (``RUN.json``) take the study run's and config's places."""
    from salad_lab.stage_eval import latest_step

    commands = []
    for v in variants:
        if "=" in v:
            v, _, probe_run = v.partition("=")
            src, study_cfg = Path(probe_run).expanduser(), Path(probe_run).expanduser().with_suffix(".json")
            if not study_cfg.is_file():
                raise SystemExit(f"{study_cfg} does not exist: a probe variant NAME=RUN needs the config it trained "
                                 f"with beside its run (as lab/scripts/ablations/ablation_denoiser_probe.py config writes it)")
        else:
            src, study_cfg = work / f"den_{v}", work / "configs" / f"den_{v}.json"
            if not study_cfg.is_file():
                have = sorted(p.stem[4:] for p in (work / "configs").glob("den_*.json"))
                raise SystemExit(f"{study_cfg} does not exist: --study-work is the study's work folder and --variants "
                                 f"its denoiser variants ({have}) or NAME=RUN for a denoiser probe")
        dest = out_dir / f"den_{v}"
        if not dest.exists():
            if not (src / "train_state.json").is_file():
                raise SystemExit(f"{src} holds no train state: the run must be where its last stage left it")
            tmp = dest.with_name(dest.name + ".tmp")
            shutil.rmtree(tmp, ignore_errors=True)
            shutil.copytree(src, tmp)
            tmp.rename(dest)
            print(f"copied {src} (step {latest_step(src)}) to {dest}")
        cfg = apply_sets(json.loads(study_cfg.read_text()), sets)
        (out_dir / f"den_{v}.json").write_text(json.dumps(cfg, indent=2) + "\n")
        task = json.loads((dest / "config.json").read_text()).get("task", {})
        commands.append(f"python -m salad_core.train denoiser --data {task.get('data', 'CORPUS')} --out {dest} "
                        f"--config {out_dir / f'den_{v}.json'} --vae {task.get('vae', 'VAE')} --no-progress --resume")
    return commands


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = ap.add_subparsers(dest="what", required=True)
    p = sub.add_parser("prepare", help="copy the study's runs and write the continuation configs")
    p.add_argument("--study-work", type=Path, required=True, help="the study's work folder (den_<variant>, configs/)")
    p.add_argument("--variants", nargs="+", required=True,
                   help="the study's denoiser variants, or NAME=RUN for a denoiser probe's run (config at RUN.json)")
    p.add_argument("--set", dest="sets", nargs="+", required=True, metavar="SECTION.KEY=VALUE")
    p.add_argument("--out-dir", type=Path, required=True)
    s = sub.add_parser("score", help="score the continued runs with a stage's protocol and record them")
    s.add_argument("--stage-eval", type=Path, required=True, help="the stage the runs continued (evaluations/G@S.json)")
    s.add_argument("--out-dir", type=Path, required=True, help="the continued runs (den_<variant>)")
    s.add_argument("--variants", nargs="+", required=True, help="the first is compared with each other one; rows of "
                   "the stage or (with --probes) denoiser probes made on it")
    s.add_argument("--probes", type=Path, default=None, help="the probe record (probes.json) holding variants that "
                   "are not rows of the stage: their figures at the stage are the probe's")
    s.add_argument("--name", required=True, help="the probe's key in the record")
    s.add_argument("--change-text", required=True, help="what the continuation changed, in words (recorded)")
    s.add_argument("--vae", type=Path, default=None, help="the frozen VAE the denoisers learned on (default: the one "
                   "each run records; give it when the run's VAE moved, e.g. salad_core/weights/ablations/vae_st_long)")
    s.add_argument("--data", type=Path, required=True, help="the study's corpus")
    s.add_argument("--out", type=Path, required=True, help="the record (JSON, one entry per --name, merged)")
    s.add_argument("--sampler", nargs="+", default=[], metavar="KEY=VALUE",
                   help="score with other sampler settings than the stage's (guidance_scale, num_steps, solver), "
                        "e.g. guidance_scale=3.5; the crops and noise stay the stage's")
    s.add_argument("--threads", type=int, default=None)
    args = ap.parse_args(argv)
    home = str(Path.home())
    command = ("python lab/scripts/ablations/ablation_continuation_probe.py " + " ".join(
        shlex.quote(str(a)) for a in (argv if argv is not None else sys.argv[1:]))).replace(home, "~")
    if args.what == "prepare":
        args.out_dir.mkdir(parents=True, exist_ok=True)
        for c in prepare(args.study_work, args.variants, parse_sets(args.sets), args.out_dir):
            print(c)
        made = args.out_dir / "prepare_command.txt"                  # every prepare of the folder, recorded by score
        lines = made.read_text().splitlines() if made.is_file() else []
        made.write_text("\n".join(lines + ([command] if command not in lines else [])) + "\n")
        return 0

    import torch

    if args.threads:
        torch.set_num_threads(args.threads)
    from salad_lab.orderings import TABLE_METRICS, paired_advantage
    from salad_lab.probes import continuation_probe_markdown, score_denoiser_continuation
    from salad_core.eval.train_evaluator import load_packaged_evaluator
    from salad_core.io import atomic_write_text
    from salad_core.text import load_text_encoder
    from salad_core.train.config import parse_overrides

    stage = json.loads(args.stage_eval.read_text())
    if stage.get("kind") != "denoiser":
        raise SystemExit(f"{args.stage_eval} is a {stage.get('kind')!r} stage: continuations are of denoiser stages")
    at_stage = dict(stage["rows"])                   # variant -> its row at the stage (a stage row or a probe's)
    probes = json.loads(args.probes.read_text()) if args.probes else {}
    for v in args.variants:
        if v not in at_stage and v in probes and probes[v].get("stage") == stage["stage"]:
            at_stage[v] = probes[v]
        if v not in at_stage:
            mine = sorted(k for k, p in probes.items() if p.get("stage") == stage["stage"])
            raise SystemExit(f"variant {v!r} is not a row of {args.stage_eval} (rows: {sorted(stage['rows'])})"
                             + (f" nor one of its probes in {args.probes} ({mine})" if args.probes else
                                "; a denoiser probe's variant needs --probes"))
        if not (args.out_dir / f"den_{v}" / "latest.json").is_file():
            raise SystemExit(f"{args.out_dir / f'den_{v}'} holds no trained run: prepare and train it first")
    evaluator = load_packaged_evaluator()[0]
    text_encoder = load_text_encoder("minilm")
    metrics = TABLE_METRICS["denoiser"]
    rows, steps = {}, set()
    sampler = parse_overrides(args.sampler, dotted=False) if args.sampler else None
    for v in args.variants:
        run = args.out_dir / f"den_{v}"
        row = score_denoiser_continuation(stage, run, vae=args.vae, label=f"{at_stage[v]['label']}, "
                                          f"{args.change_text}", data=args.data, evaluator=evaluator,
                                          text_encoder=text_encoder, sampler=sampler)
        row["at_stage"] = {m: at_stage[v]["summary"][m] for m in metrics}
        row["run"] = row["run"].replace(home, "~")
        cfg = args.out_dir / f"den_{v}.json"
        row["trained_config"] = json.loads(cfg.read_text()) if cfg.is_file() else None
        rows[v] = row
        steps.add(row["steps"])
        print(f"{v} at {row['steps']}:", ", ".join(f"{m} {row['summary'][m][0]:.3f} ± {row['summary'][m][1]:.3f} "
                                                     f"(at {stage['steps']} {row['at_stage'][m][0]:.3f})"
                                                     for m in metrics))
    if len(steps) != 1:
        raise SystemExit(f"the continued runs stopped at different steps {sorted(steps)}: train them to one budget")
    first = args.variants[0]
    paired = {}
    for b in args.variants[1:]:
        for m in metrics:
            probe = paired_advantage(rows[first]["values"][m], rows[b]["values"][m], m)
            at = paired_advantage(at_stage[first]["values"][m], at_stage[b]["values"][m], m)
            paired[f"{first} vs {b}, {m}"] = {"probe": list(probe), "at_stage": list(at)}
    made = args.out_dir / "prepare_command.txt"
    prepared = made.read_text().split("\n") if made.is_file() else ["(prepared by hand: see each row's trained_config)"]
    record = json.loads(args.out.read_text()) if args.out.is_file() else {}
    record[args.name] = {"stage_eval": str(args.stage_eval), "stage": stage["stage"], "from_step": int(stage["steps"]),
                         "steps": steps.pop(), "change_text": args.change_text, "sampler": sampler or {},
                         "rows": rows, "paired": paired,
                         "commands": [c for c in prepared if c] + [command]}
    args.out.parent.mkdir(parents=True, exist_ok=True)
    atomic_write_text(args.out, json.dumps(record, indent=1) + "\n")
    print(continuation_probe_markdown({args.name: record[args.name]}))
    print(f"recorded in {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
