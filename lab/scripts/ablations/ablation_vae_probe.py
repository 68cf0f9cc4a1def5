#!/usr/bin/env python
"""A probe beside the ablation study (issue 24): one VAE variant changed, trained to a stage's budget, scored
with exactly that stage's protocol, recorded in the study's probes.json.

Two steps, both resumable:

    # 1. write the probe's training config (a study variant's config with changes) and print the train command
    python lab/scripts/ablations/ablation_vae_probe.py config --study-configs ~/salad-runs/ablations_v3/configs \\
        --variant pose_long --set model.pose_width=46 --out ~/salad-runs/abl_probe/vae_pose_matched.json
    python -m salad_core.train vae --data CORPUS --out ~/salad-runs/abl_probe/vae_pose_matched \\
        --config ~/salad-runs/abl_probe/vae_pose_matched.json --resume
    # 2. score it with the stage's protocol and record it
    python lab/scripts/ablations/ablation_vae_probe.py score --stage-eval salad_core/weights/ablations/evaluations/vaes@6000.json \\
        --run ~/salad-runs/abl_probe/vae_pose_matched --name pose_matched --variant pose_long \\
        --set model.pose_width=46 --label "pose-vector VAE, parameters matched" --data CORPUS \\
        --out lab/records/ablations_v2/probes.json

The study's configs (``<work>/configs/vae_<variant>.json``) are the exact configs its runs trained with; the
probe changes only what ``--set`` names (dotted keys into the config, JSON values). The record keeps both
commands, so the probe can be made again on a new machine.
"""
from __future__ import annotations

import argparse
import json
import shlex
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[3]
sys.path.insert(0, str(REPO))
sys.path.insert(0, str(REPO / "lab"))   # salad_lab


def parse_sets(items: list[str]) -> dict:
    """``["model.pose_width=46"]`` -> ``{"model.pose_width": 46}`` (values read as JSON, else as text)."""
    from salad_core.train.config import parse_overrides

    return parse_overrides(items, dotted=True)


def apply_sets(config: dict, sets: dict) -> dict:
    """A copy of ``config`` with each dotted key of ``sets`` replaced; the section must exist."""
    cfg = json.loads(json.dumps(config))
    for key, value in sets.items():
        section, _, name = key.partition(".")
        if section not in cfg or not isinstance(cfg[section], dict):
            raise ValueError(f"--set {key}: the config has no section {section!r} (sections: {sorted(cfg)})")
        cfg[section][name] = value
    return cfg


def probe_config(study_configs: Path, prefix: str, variant: str, sets: dict) -> dict:
    """The study's config ``<study_configs>/<prefix>_<variant>.json`` with ``sets`` applied (``prefix``: ``vae`` or
    ``den``); SystemExit naming the study's variants when there is no such config."""
    src = study_configs / f"{prefix}_{variant}.json"
    if not src.is_file():
        have = sorted(q.stem[len(prefix) + 1:] for q in study_configs.glob(f"{prefix}_*.json"))
        raise SystemExit(f"{src} does not exist: --study-configs is the study's <work>/configs folder and --variant "
                         f"one of its {prefix} variants ({have})")
    return apply_sets(json.loads(src.read_text()), sets)


def write_probe_config(study_configs: Path, prefix: str, variant: str, sets: dict, out: Path) -> Path:
    """Write :func:`probe_config` to ``out``; return the probe's run folder (``out`` without ``.json``)."""
    cfg = probe_config(study_configs, prefix, variant, sets)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(cfg, indent=2) + "\n")
    return out.with_suffix("")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = ap.add_subparsers(dest="what", required=True)
    c = sub.add_parser("config", help="write the probe's training config")
    c.add_argument("--study-configs", type=Path, required=True, help="the study's <work>/configs folder")
    c.add_argument("--variant", required=True, help="the study's VAE variant the probe changes (e.g. pose_long)")
    c.add_argument("--set", dest="sets", nargs="+", required=True, metavar="SECTION.KEY=VALUE")
    c.add_argument("--out", type=Path, required=True)
    s = sub.add_parser("score", help="score a trained probe with a stage's protocol and record it")
    s.add_argument("--stage-eval", type=Path, required=True, help="the stage evaluation file (evaluations/G@S.json)")
    s.add_argument("--run", type=Path, required=True, help="the probe's training run")
    s.add_argument("--name", required=True, help="the probe's key in the record")
    s.add_argument("--variant", required=True, help="the stage's variant the probe changes")
    s.add_argument("--set", dest="sets", nargs="+", required=True, metavar="SECTION.KEY=VALUE",
                   help="what the probe changed (recorded)")
    s.add_argument("--label", required=True)
    s.add_argument("--data", type=Path, required=True, help="the study's corpus")
    s.add_argument("--out", type=Path, required=True, help="the probe record (probes.json)")
    s.add_argument("--evaluator", type=Path, default=None,
                   help="evaluator folder (default: the packaged procedural-corpus evaluator, the study's)")
    s.add_argument("--threads", type=int, default=1)
    args = ap.parse_args(argv)
    sets = parse_sets(args.sets)
    if args.what == "config":
        run = write_probe_config(args.study_configs, "vae", args.variant, sets, args.out)
        print(f"wrote {args.out}; train it with:\n  python -m salad_core.train vae --data CORPUS --out {run} "
              f"--config {args.out} --resume")
        return 0
    import torch

    from salad_lab.probes import probe_markdown, record_probe, score_vae_probe
    from salad_core.eval.train_evaluator import load_packaged_evaluator

    torch.set_num_threads(args.threads)
    stage = json.loads(args.stage_eval.read_text())
    evaluator = load_packaged_evaluator(args.evaluator)[0]
    row = score_vae_probe(stage, args.run, label=args.label, change=sets, base_variant=args.variant, data=args.data,
                          evaluator=evaluator)
    config = args.run / "config.json"
    home = str(Path.home())
    run = str(args.run).replace(home, "~")
    train_cmd = (f"python lab/scripts/ablations/ablation_vae_probe.py config --study-configs STUDY_WORK/configs --variant "
                 f"{args.variant} --set {' '.join(shlex.quote(a) for a in args.sets)} --out {run}.json && "
                 f"python -m salad_core.train vae --data CORPUS --out {run} --config {run}.json --resume")
    score_cmd = ("python lab/scripts/ablations/ablation_vae_probe.py " + " ".join(shlex.quote(str(a)) for a in
                                                                (argv if argv is not None else sys.argv[1:])))
    score_cmd = score_cmd.replace(home, "~")
    path = record_probe(args.out, args.name, {**row, "trained_config": json.loads(config.read_text())
                                              if config.is_file() else None},
                        commands=[train_cmd, score_cmd])
    print(probe_markdown(stage, {args.name: row}, [args.variant] + [v for v in stage["rows"] if v != args.variant]))
    print(f"recorded in {path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
