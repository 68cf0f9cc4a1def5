#!/usr/bin/env python
"""A denoiser probe beside the ablation study (issue 24): one study variant's denoiser trained from scratch to a
stage's budget on another frozen VAE (and optionally with config changes), scored with exactly that stage's protocol,
recorded in the study's probes.json beside the VAE probes.

The question it was written for: the study's "w/o ST-latent" denoiser learns on the pose-vector VAE, which has 17x
the skeleton-aware VAE's parameters; does the row change on the parameter-matched pose-vector VAE (the VAE probe
``pose_matched``)? Two steps, both resumable:

    # 1. write the probe's training config (the study variant's, with --set) and print the train command
    python lab/scripts/ablations/ablation_denoiser_probe.py config --study-configs ~/salad-runs/ablations_v3/configs \\
        --variant no_st --vae ~/salad-runs/abl_probe/vae_pose_matched \\
        --out ~/salad-runs/abl_probe/den_no_st_matched.json
    python -m salad_core.train denoiser --data CORPUS --out ~/salad-runs/abl_probe/den_no_st_matched \\
        --config ~/salad-runs/abl_probe/den_no_st_matched.json --vae ~/salad-runs/abl_probe/vae_pose_matched \\
        --no-progress --resume
    # 2. score it with the stage's protocol and record it
    python lab/scripts/ablations/ablation_denoiser_probe.py score --stage-eval salad_core/weights/ablations/evaluations/denoisers@8000.json \\
        --run ~/salad-runs/abl_probe/den_no_st_matched --vae ~/salad-runs/abl_probe/vae_pose_matched \\
        --name no_st_matched --variant no_st --vae-label "the pose_matched probe's VAE" \\
        --label "w/o ST-latent on the parameter-matched pose-vector VAE" --data CORPUS \\
        --out lab/records/ablations_v2/probes.json

``--set`` changes of the cache folder and thread count do not change what is trained; any other is recorded as part
of the probe's change. The record keeps both commands, so the probe can be made again on a new machine.
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
sys.path.insert(0, str(Path(__file__).resolve().parent))   # sibling scripts
from ablation_vae_probe import parse_sets, write_probe_config  # noqa: E402  (the VAE probe's config writing, shared)

#: config keys that change where or how fast a run trains, not what it learns (left out of the recorded change)
NEUTRAL_KEYS = ("train.latent_cache_dir", "train.num_threads", "train.num_workers", "train.progress")


def write_study_configs(recipe_path: Path, work: Path) -> int:
    """Write ``work/configs/den_<v>.json`` (the config each denoiser variant trained its final stage with) and
    ``work/study_vaes.json`` (variant -> the frozen VAE folder it learned on), from the study's recipe and its
    evaluation files; what ``config`` and ``lab/scripts/ablations/probe_denoisers.sh`` need when ``work`` holds only the groups
    ``lab/scripts/ablations/train_ablations.py`` restored (no run folders). An existing config that differs is not overwritten."""
    from salad_lab import load_staged_recipe
    from salad_lab.runner import final_denoiser_jobs

    try:
        jobs = final_denoiser_jobs(load_staged_recipe(recipe_path), work)
    except RuntimeError as err:
        raise SystemExit(f"{work}: {err} (restore the study first: lab/scripts/ablations/train_ablations.py --recipe "
                         f"{recipe_path} --data CORPUS --work {work})")
    (work / "configs").mkdir(parents=True, exist_ok=True)
    vaes = {}
    for job in jobs:
        path = work / "configs" / f"{job.run_dir.name}.json"
        text = json.dumps(job.config, indent=2) + "\n"
        if path.is_file() and json.loads(path.read_text()) != job.config:
            raise SystemExit(f"{path} exists and differs from the recipe's final-stage config: not overwritten")
        path.write_text(text)
        vae = Path(job.depends_on)   # the packaged model's stem, as the study's own runs recorded it
        vaes[job.variant.name] = str(vae / "vae" if (vae / "vae.safetensors").is_file() else vae)
    (work / "study_vaes.json").write_text(json.dumps(vaes, indent=2) + "\n")
    print(f"wrote {len(jobs)} denoiser configs to {work / 'configs'} and {work / 'study_vaes.json'}")
    return 0


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = ap.add_subparsers(dest="what", required=True)
    c = sub.add_parser("config", help="write the probe's training config and print its train command")
    c.add_argument("--study-configs", type=Path, required=True, help="the study's <work>/configs folder")
    c.add_argument("--variant", required=True, help="the study's denoiser variant the probe changes (e.g. no_st)")
    c.add_argument("--vae", type=Path, required=True, help="the frozen VAE the probe learns on (run or exported)")
    c.add_argument("--set", dest="sets", nargs="+", default=[], metavar="SECTION.KEY=VALUE")
    c.add_argument("--out", type=Path, required=True, help="the config file; the run is this path without .json")
    w = sub.add_parser("study-configs", help="a study restored on a new machine: write its denoisers' configs and "
                                             "the VAE each learned on (WORK/configs/den_<v>.json, WORK/study_vaes.json)")
    w.add_argument("--recipe", type=Path, default=REPO / "lab" / "configs" / "ablations_v2.json", help="the study's recipe")
    w.add_argument("--work", type=Path, required=True, help="the study's work folder (its groups restored)")
    s = sub.add_parser("score", help="score a trained probe with a stage's protocol and record it")
    s.add_argument("--stage-eval", type=Path, required=True, help="the stage evaluation file (evaluations/G@S.json)")
    s.add_argument("--run", type=Path, required=True, help="the probe's denoiser run")
    s.add_argument("--vae", type=Path, required=True, help="the frozen VAE it learned on")
    s.add_argument("--vae-label", required=True, help="what that VAE is, in words (recorded as the change)")
    s.add_argument("--name", required=True, help="the probe's key in the record")
    s.add_argument("--variant", required=True, help="the stage's variant the probe changes")
    s.add_argument("--set", dest="sets", nargs="+", default=[], metavar="SECTION.KEY=VALUE",
                   help="the config changes it trained with (recorded, except cache folder and threads)")
    s.add_argument("--label", required=True)
    s.add_argument("--data", type=Path, required=True, help="the study's corpus")
    s.add_argument("--out", type=Path, required=True, help="the probe record (probes.json)")
    s.add_argument("--threads", type=int, default=1)
    args = ap.parse_args(argv)
    if args.what == "study-configs":
        return write_study_configs(args.recipe, args.work)
    sets = parse_sets(args.sets)
    home = str(Path.home())
    if args.what == "config":
        from salad_core.train.assemble import vae_source

        try:
            vae_source(args.vae)
        except FileNotFoundError as err:
            ap.error(f"--vae {args.vae}: {err} (train the probe's VAE first)")
        run = write_probe_config(args.study_configs, "den", args.variant, sets, args.out)
        print(f"wrote {args.out}; train it with:\n  python -m salad_core.train denoiser --data CORPUS --out {run} "
              f"--config {args.out} --vae {args.vae} --no-progress --resume")
        return 0
    import torch

    from salad_lab.probes import probe_markdown, record_probe, score_denoiser_probe

    torch.set_num_threads(args.threads)
    stage = json.loads(args.stage_eval.read_text())
    change = {"vae": args.vae_label, **{k: v for k, v in sets.items() if k not in NEUTRAL_KEYS}}
    row = score_denoiser_probe(stage, args.run, vae=args.vae, label=args.label, change=change,
                               base_variant=args.variant, data=args.data)
    config = args.run / "config.json"
    run, vae = (str(p).replace(home, "~") for p in (args.run, args.vae))
    set_text = f" --set {' '.join(shlex.quote(a) for a in args.sets)}" if args.sets else ""
    train_cmd = (f"python lab/scripts/ablations/ablation_denoiser_probe.py config --study-configs STUDY_WORK/configs --variant "
                 f"{args.variant} --vae {vae}{set_text} --out {run}.json && python -m salad_core.train denoiser "
                 f"--data CORPUS --out {run} --config {run}.json --vae {vae} --no-progress --resume")
    score_cmd = ("python lab/scripts/ablations/ablation_denoiser_probe.py " + " ".join(
        shlex.quote(str(a)) for a in (argv if argv is not None else sys.argv[1:]))).replace(home, "~")
    row = {**row, "run": run, "vae": vae,
           "trained_config": json.loads(config.read_text()) if config.is_file() else None}
    path = record_probe(args.out, args.name, row, commands=[train_cmd, score_cmd])
    print(probe_markdown(stage, {args.name: row}, [args.variant] + [v for v in stage["rows"] if v != args.variant]))
    print(f"recorded in {path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
