#!/usr/bin/env python
"""Fine-tune a KeyMotion MMAE with the foot-contact term (issue 22), then assemble a pipeline to measure it.

``scripts/keymotion_flight_chain.py`` measured where KeyMotion 0.2's feet start to slide: test clips move
their planted feet at 0.01 m/s, the MMAE's in-filling of the clips' own keyframes at 0.14 m/s. This starts
an MMAE from the weights of a trained KeyMotion pipeline (default: the shipped ``salad_core/weights/
keymotion``; same architecture, its normalisation kept), trains it with the recipe's MMAE settings
(``configs/v2_keymotion.json``: keyframe ratio, keyframe noise, batch, buckets) plus
``MMAEConfig.lambda_foot`` (:func:`salad_core.keymotion.models.foot_contact_loss`: planted feet stay put)
at a constant learning rate, and with ``--export`` writes a pipeline folder: the source's keyframe VAE and
PST with the new MMAE.

    python scripts/finetune_keymotion_mmae.py --data CORPUS --out RUN --steps 3000                 # train (resumable)
    python scripts/finetune_keymotion_mmae.py --data CORPUS --out RUN --steps 3000 --export DIR    # then assemble

CORPUS must be the corpus the source pipeline was trained on (KeyMotion 0.2: corpus generator 2.7,
``python -m salad_core.cli corpus build --out CORPUS --size default --seed 0`` at 4736db4). Run it again with
``--resume`` after an interruption.
"""
from __future__ import annotations

import argparse
import json
import logging
import sys
from dataclasses import replace
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]


def main(argv=None, *, text_encoder=None) -> int:
    """``text_encoder``: an encoder object instead of the recipe's (tests)."""
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--data", required=True, type=Path, help="corpus the source pipeline was trained on")
    ap.add_argument("--out", required=True, type=Path, help="run folder of the fine-tuned MMAE")
    ap.add_argument("--source", type=Path, default=None,
                    help="KeyMotion pipeline folder to start from (default: the shipped weights)")
    ap.add_argument("--recipe", type=Path, default=REPO / "configs" / "v2_keymotion.json",
                    help="KeyMotion recipe whose 'mmae' section sets the model and training settings")
    ap.add_argument("--steps", type=int, default=3000)
    ap.add_argument("--lr", type=float, default=1e-4, help="constant after a 200-step warm-up (the recipe ended "
                                                             "at 1e-4)")
    ap.add_argument("--lambda-foot", type=float, default=5.0, help="weight of the foot-contact term")
    ap.add_argument("--threads", type=int, default=None, help="torch threads (default: the recipe's)")
    ap.add_argument("--resume", action="store_true")
    ap.add_argument("--export", type=Path, default=None, help="write the pipeline with the new MMAE here (fp16)")
    args = ap.parse_args(argv)
    if args.steps < 1:
        ap.error(f"--steps {args.steps}: use an integer >= 1")
    if not args.lambda_foot >= 0:
        ap.error(f"--lambda-foot {args.lambda_foot}: use a number >= 0")
    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(levelname)s %(name)s: %(message)s")

    from salad_core.keymotion.mmae import MMAEConfig
    from salad_core.keymotion.pipeline import DEFAULT_WEIGHTS_DIR
    from salad_core.keymotion.train import KeyMotionRecipe, train_mmae

    source = args.source or DEFAULT_WEIGHTS_DIR
    if not (source / "mmae.safetensors").is_file():
        ap.error(f"--source {source}: no mmae.safetensors (a KeyMotion pipeline folder is needed)")
    doc = json.loads(args.recipe.read_text())
    recipe = KeyMotionRecipe.from_doc(doc)
    overrides = {"max_steps": args.steps, "lr": args.lr, "milestones": (), "warmup_steps": 200,
                 "init_from": str(source), "progress": False}
    if args.threads is not None:
        overrides["num_threads"] = args.threads
    train_cfg = replace(recipe.mmae_train, **overrides)
    model_cfg = replace(recipe.mmae_model or MMAEConfig(), lambda_foot=args.lambda_foot)
    num_keyframes = json.loads((source / "kf_vae.json").read_text())["config"].get("num_keyframes", 20)
    encoder = text_encoder if text_encoder is not None else doc.get("text_encoder", "minilm")
    result = train_mmae(args.data, args.out, model_cfg, train_cfg, text_encoder=encoder, resume=args.resume,
                        num_keyframes=num_keyframes)
    print(f"mmae: step {result.step}, best val {result.best_val} (step {result.best_step}), "
          f"{result.steps_per_s:.2f} steps/s -> {result.out_dir}")
    if result.interrupted:
        return 130
    if args.export is not None:
        from salad_core.keymotion.export import export_with_component

        export_with_component(source, "mmae", args.out, args.export, text_encoder=text_encoder)
        print(f"pipeline with the fine-tuned MMAE -> {args.export}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
