#!/usr/bin/env python
"""Fine-tune a KeyMotion PST with the side cue (issue 22), then assemble a pipeline to measure it.

The shipped PST ignores "left" and "right" (``salad_core/keymotion/sides.py`` has the measurement).
This starts a PST with ``side_cue=True`` from the weights of a trained KeyMotion pipeline (default: the
shipped ``salad_core/weights/keymotion``; its PST loads with the side embedding at zero, so step 0 is
exactly that model), trains it on the *same* keyframe VAE's latents with the recipe's PST settings
(``configs/v2_keymotion.json``: model, batch, text dropout, length buckets) at a constant learning rate,
and with ``--export`` writes a pipeline folder: the source's keyframe VAE and MMAE with the new PST.

    python scripts/finetune_keymotion_sides.py --data CORPUS --out RUN --steps 3000            # train (resumable)
    python scripts/finetune_keymotion_sides.py --data CORPUS --out RUN --steps 3000 --export DIR   # then assemble

CORPUS must be the corpus the source pipeline was trained on (KeyMotion 0.2: corpus generator 2.7,
``scripts/train_v2.sh WORK data`` at 4736db4). Run it again with ``--resume`` after an interruption.
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
    ap.add_argument("--out", required=True, type=Path, help="run folder of the fine-tuned PST")
    ap.add_argument("--source", type=Path, default=None,
                    help="KeyMotion pipeline folder to start from (default: the shipped weights)")
    ap.add_argument("--recipe", type=Path, default=REPO / "configs" / "v2_keymotion.json",
                    help="KeyMotion recipe whose 'pst' section sets the model and training settings")
    ap.add_argument("--steps", type=int, default=3000)
    ap.add_argument("--lr", type=float, default=2e-4, help="constant after a 200-step warm-up")
    ap.add_argument("--threads", type=int, default=None, help="torch threads (default: the recipe's)")
    ap.add_argument("--resume", action="store_true")
    ap.add_argument("--export", type=Path, default=None, help="write the pipeline with the new PST here (fp16)")
    args = ap.parse_args(argv)
    if args.steps < 1:
        ap.error(f"--steps {args.steps}: use an integer >= 1")
    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(levelname)s %(name)s: %(message)s")

    from salad_core.keymotion.pipeline import DEFAULT_WEIGHTS_DIR
    from salad_core.keymotion.train import KeyMotionRecipe, train_pst

    source = args.source or DEFAULT_WEIGHTS_DIR
    if not (source / "pst.safetensors").is_file():
        ap.error(f"--source {source}: no pst.safetensors (a KeyMotion pipeline folder is needed)")
    doc = json.loads(args.recipe.read_text())
    recipe = KeyMotionRecipe.from_doc(doc)
    if recipe.pst_model is None:
        ap.error(f"--recipe {args.recipe}: its 'pst' section has no 'model' (the source PST's architecture is needed)")
    overrides = {"max_steps": args.steps, "lr": args.lr, "milestones": (), "warmup_steps": 200,
                 "init_from": str(source), "progress": False}
    if args.threads is not None:
        overrides["num_threads"] = args.threads
    train_cfg = replace(recipe.pst_train, **overrides)
    model_cfg = replace(recipe.pst_model, side_cue=True)
    encoder = text_encoder if text_encoder is not None else doc.get("text_encoder", "minilm")
    result = train_pst(args.data, args.out, source / "kf_vae", model_cfg, train_cfg, text_encoder=encoder,
                       resume=args.resume)
    print(f"pst: step {result.step}, best val {result.best_val} (step {result.best_step}), "
          f"{result.steps_per_s:.2f} steps/s -> {result.out_dir}")
    if result.interrupted:
        return 130
    if args.export is not None:
        from salad_core.keymotion.export import export_with_component

        export_with_component(source, "pst", args.out, args.export, text_encoder=text_encoder)
        print(f"pipeline with the side-cue PST -> {args.export}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
