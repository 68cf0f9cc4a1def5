#!/usr/bin/env python
"""Fine-tune one stage of a trained KeyMotion pipeline with extra loss terms (issue 22), then assemble a pipeline
with it to measure.

``lab/scripts/keymotion/keymotion_flight_chain.py`` measured where KeyMotion 0.2 loses the jumps' flight and starts to slide its
feet: the MMAE's in-filling of the clips' own keyframes already slides (0.14 m/s against 0.01), and the keyframe
VAE's decoded poses halve the flight (-3.30 m/s^2 against -7.66 with the true poses). Two stages can be fine-tuned:

* ``--stage mmae``: :attr:`MMAEConfig.lambda_foot` (:func:`salad_core.keymotion.models.foot_contact_loss`:
  planted feet stay put) and ``lambda_foot_vel`` (:func:`~salad_core.keymotion.models.planted_foot_velocity_loss`:
  the ground truth's velocity where a foot is truly still; ``--fixed-keyframes`` trains at generation's density), with the recipe's MMAE settings (keyframe ratio, keyframe noise, batch, buckets);
  ``--roundtrip P`` gives a share ``P`` of the items the source keyframe VAE's reconstruction of their keyframes
  (``KeyMotionTrainConfig.keyframe_roundtrip``: the errors generation makes) and selects the VAE's fixed number
  of keyframes for every item (``keyframe_ratio`` 0).
* ``--stage pst``: ``--side-cue`` adds the side cue (:attr:`PSTConfig.side_cue`: the shipped PST ignores "left"
  and "right", ``salad_core/keymotion/sides.py`` has the measurement; its embedding starts at zero, so step 0 is
  exactly the source PST), trained on the source keyframe VAE's latents with the recipe's PST settings (text
  dropout, length buckets); without it the PST just trains on. ``--latent-norm`` gives the PST latent
  normalisation (:attr:`PSTConfig.latent_norm`); a source PST without it cannot start such a model, so add
  ``--scratch``: a new PST trained from its initialisation with the recipe's schedule (learning rate, decay
  milestones, warm-up; ``--steps`` then counts the whole run, e.g. the recipe's 60,000), on the source keyframe
  VAE's latents; ``--kf-vae RUN`` trains it on another keyframe VAE (a run folder, e.g. a wider latent; the
  recipe's PST section must give its latent shape), and ``--export`` then assembles that VAE, the new PST and the
  source's MMAE.
  ``--side-canonical`` trains on side-canonical data (:attr:`PSTConfig.side_canonical`: an item whose caption
  names the left kind first is replaced by its mirror image; the pipeline mirrors such prompts and the motions
  back), fine-tuning the source PST (same architecture).
* ``--stage mmae --scratch``: a new MMAE of the recipe's architecture (e.g. ``lab/configs/keymotion_mmae_large.json``,
  wider and deeper than the shipped one) trained from its initialisation with the recipe's schedule (``--steps``
  the whole run), keeping ``--lambda-foot`` and ``--roundtrip``; ``--export`` assembles it with the source's keyframe
  VAE and PST (the MMAE is trained on the corpus's motion, independent of both).
* ``--stage kf_vae --scratch``: a new keyframe VAE of the recipe's architecture (e.g. ``lab/configs/keymotion-v4-absolute.json``:
  absolute keyframe timing) trained whole from its initialisation with the recipe's schedule (``--steps`` the whole
  run); a PST for it then comes from ``--stage pst --scratch --kf-vae RUN``.
* ``--stage kf_vae``: :attr:`KeyframeVAEConfig.lambda_root`, ``lambda_local_vel``, ``lambda_contact`` and
  ``lambda_feet_height`` (the root, joint-velocity, foot-contact and foot-height channels weighed again), by default with the encoder frozen
  (``--parts decoder``) so the source's PST, trained on its latents, still fits. ``--latent-noise S`` adds
  Gaussian noise of std ``S`` to the latent the decoder reads (:attr:`KeyframeVAEConfig.latent_noise`): the
  decoder learns to decode latents near the posteriors too, as a PST's samples are (give ``--source`` the
  pipeline whose PST will read it).

Either starts from the source pipeline's model of that stage (default: the shipped ``salad_core/weights/
keymotion``; same architecture, its normalisation kept) at a constant learning rate after a 200-step warm-up
(default 1e-4, the PST 2e-4),
and with ``--export`` writes a pipeline folder: the source's other two models with the new one, and in its
``runs.json`` the source's run records with the new model's (salad_core.keymotion.export.export_with_component).

    python lab/scripts/keymotion/finetune_keymotion.py --stage mmae --data CORPUS --out RUN --steps 3000      # train (resumable)
    python lab/scripts/keymotion/finetune_keymotion.py --stage pst --side-cue --data CORPUS --out RUN --steps 3000
    python lab/scripts/keymotion/finetune_keymotion.py --stage pst --latent-norm --scratch --data CORPUS --out RUN --steps 60000
    python lab/scripts/keymotion/finetune_keymotion.py --stage pst --latent-norm --scratch --kf-vae VAE_RUN --recipe RECIPE \\
        --data CORPUS --out RUN --steps 60000 --export DIR          # a PST on another keyframe VAE (its recipe's PST)
    python lab/scripts/keymotion/finetune_keymotion.py --stage kf_vae --lambda-feet-height 5 --data CORPUS \\
        --out RUN --steps 4000 --export DIR                                                    # train, then assemble

CORPUS must be the corpus the source pipeline was trained on (KeyMotion 0.2: corpus generator 2.7,
``python -m salad_core.cli corpus build --out CORPUS --size default --seed 0`` at 4736db4). Run it again with
``--resume`` after an interruption (with the same arguments).
"""
from __future__ import annotations

import argparse
import json
import logging
import sys
from dataclasses import replace
from pathlib import Path

REPO = Path(__file__).resolve().parents[3]

#: per stage: the flags (and model config fields) of its extra loss weights
LOSS_FLAGS = {"mmae": ("lambda_foot", "lambda_foot_vel"), "pst": (),
              "kf_vae": ("lambda_root", "lambda_local_vel", "lambda_contact", "lambda_feet_height",
                         "latent_noise")}
#: per stage: its other flags
STAGE_FLAGS = {"mmae": ("roundtrip", "scratch", "fixed_keyframes"), "kf_vae": ("parts", "scratch"), "pst": ("side_cue", "side_canonical", "latent_norm", "scratch",
                                                                                      "kf_vae", "no_middle_skip")}
#: the learning rate a stage gets when --lr is not given (the PST's probe of session 20 ran at 2e-4)
DEFAULT_LR = {"mmae": 1e-4, "kf_vae": 1e-4, "pst": 2e-4}
#: the weight a flag gets when not given
DEFAULT_WEIGHTS = {"lambda_foot": 5.0, "lambda_foot_vel": 0.0, "lambda_root": 0.0, "lambda_local_vel": 0.0, "lambda_contact": 0.0,
                   "lambda_feet_height": 0.0, "latent_noise": 0.0}


def main(argv=None, *, text_encoder=None) -> int:
    """``text_encoder``: an encoder object instead of the recipe's (tests)."""
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--stage", required=True, choices=sorted(LOSS_FLAGS), help="the model to fine-tune")
    ap.add_argument("--data", required=True, type=Path, help="corpus the source pipeline was trained on")
    ap.add_argument("--out", required=True, type=Path, help="run folder of the fine-tuned model")
    ap.add_argument("--source", type=Path, default=None,
                    help="KeyMotion pipeline folder to start from (default: the shipped weights)")
    ap.add_argument("--recipe", type=Path, default=REPO / "configs" / "keymotion-0.2.json",
                    help="KeyMotion recipe whose section of the stage sets the model and training settings")
    ap.add_argument("--steps", type=int, default=3000)
    ap.add_argument("--lr", type=float, default=None, help="constant after a 200-step warm-up (default 1e-4, where "
                                                             "the recipe's stages ended; the PST 2e-4)")
    ap.add_argument("--lambda-foot", type=float, default=None, help="mmae: weight of the foot-contact term (5)")
    ap.add_argument("--lambda-foot-vel", type=float, default=None,
                    help="mmae: weight of the planted-foot velocity error (truly still feet only; 0)")
    ap.add_argument("--fixed-keyframes", action="store_const", const=True, default=None,
                    help="mmae: train with the keyframe VAE's fixed number of keyframes per item (the density "
                         "generation uses: 20 of 80-196 frames), not the recipe's ratio")
    ap.add_argument("--side-cue", action="store_const", const=True, default=None,
                    help="pst: add the side cue (PSTConfig.side_cue) to the source PST")
    ap.add_argument("--side-canonical", action="store_const", const=True, default=None,
                    help="pst: train on side-canonical data (PSTConfig.side_canonical: items whose caption names "
                         "the left kind first are replaced by their mirror images)")
    ap.add_argument("--no-middle-skip", action="store_const", const=True, default=None,
                    help="pst, with --scratch: drop the degenerate middle skip pair (PSTConfig.middle_skip=False)")
    ap.add_argument("--latent-norm", action="store_const", const=True, default=None,
                    help="pst: latent normalisation (PSTConfig.latent_norm; with a source PST without it, --scratch)")
    ap.add_argument("--scratch", action="store_const", const=True, default=None,
                    help="pst, mmae: train a new model (the recipe's architecture and schedule) instead of starting "
                         "from the source's")
    ap.add_argument("--kf-vae", type=Path, default=None,
                    help="pst, with --scratch: the keyframe VAE run folder to train on (default: the source's); "
                         "--export then assembles it with the new PST and the source's MMAE")
    ap.add_argument("--roundtrip", type=float, default=None,
                    help="mmae: share of items whose input keyframes the source's keyframe VAE reconstructs (0)")
    ap.add_argument("--lambda-root", type=float, default=None, help="kf_vae: extra weight of the root channels (0)")
    ap.add_argument("--lambda-local-vel", type=float, default=None,
                    help="kf_vae: extra weight of the joint-velocity channels (0)")
    ap.add_argument("--lambda-contact", type=float, default=None,
                    help="kf_vae: extra weight of the foot-contact channels (0)")
    ap.add_argument("--lambda-feet-height", type=float, default=None,
                    help="kf_vae: extra weight of the contact joints' height channels (0)")
    ap.add_argument("--latent-noise", type=float, default=None,
                    help="kf_vae: std of the noise added to the latent the decoder reads (0; "
                         "KeyframeVAEConfig.latent_noise)")
    ap.add_argument("--parts", choices=("decoder", "all"), default=None,
                    help="kf_vae: 'decoder' (default) freezes the encoder so the source's PST still fits")
    ap.add_argument("--rest-padding", type=float, default=None,
                    help="share of the training items that are whole clips held still before and after at a longer "
                         "length (KeyMotionTrainConfig.rest_padding; any stage)")
    ap.add_argument("--threads", type=int, default=None, help="torch threads (default: the recipe's)")
    ap.add_argument("--resume", action="store_true")
    ap.add_argument("--export", type=Path, default=None, help="write the pipeline with the new model here (fp16)")
    args = ap.parse_args(argv)
    if args.steps < 1:
        ap.error(f"--steps {args.steps}: use an integer >= 1")
    allowed = set(LOSS_FLAGS[args.stage] + STAGE_FLAGS[args.stage])
    for stage, flags in LOSS_FLAGS.items():
        for flag in flags + STAGE_FLAGS[stage]:
            if flag not in allowed and getattr(args, flag) is not None:
                ap.error(f"--{flag.replace('_', '-')} is for --stage {stage}, not {args.stage}")
    weights = {}
    for flag in LOSS_FLAGS[args.stage]:
        value = getattr(args, flag)
        if value is None and args.scratch:              # a new model keeps the recipe's weights
            continue
        value = DEFAULT_WEIGHTS[flag] if value is None else value
        if not value >= 0:
            ap.error(f"--{flag.replace('_', '-')} {value}: use a number >= 0")
        weights[flag] = value
    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(levelname)s %(name)s: %(message)s")

    from salad_core.keymotion.kf_vae import KeyframeVAEConfig
    from salad_core.keymotion.mmae import MMAEConfig
    from salad_core.keymotion.pipeline import DEFAULT_WEIGHTS_DIR
    from salad_core.keymotion.train import KeyMotionRecipe, train_kf_vae, train_mmae, train_pst

    source = args.source or DEFAULT_WEIGHTS_DIR
    if not (source / f"{args.stage}.safetensors").is_file():
        ap.error(f"--source {source}: no {args.stage}.safetensors (a KeyMotion pipeline folder is needed)")
    doc = json.loads(args.recipe.read_text())
    recipe = KeyMotionRecipe.from_doc(doc)
    encoder = text_encoder if text_encoder is not None else doc.get("text_encoder", "minilm")
    lr = DEFAULT_LR[args.stage] if args.lr is None else args.lr
    overrides = {"max_steps": args.steps, "lr": lr, "milestones": (), "warmup_steps": 200,
                 "init_from": str(source), "progress": False}
    if args.threads is not None:
        overrides["num_threads"] = args.threads
    if args.rest_padding is not None:
        if not 0.0 <= args.rest_padding <= 0.9:
            ap.error(f"--rest-padding {args.rest_padding}: use a share in [0, 0.9]")
    if args.scratch:                        # a new model: the recipe's schedule; --steps counts the whole run
        overrides = {k: v for k, v in overrides.items() if k in ("max_steps", "progress", "num_threads")}
        if args.lr is not None:
            overrides["lr"] = args.lr
    if args.rest_padding is not None:
        overrides["rest_padding"] = args.rest_padding
    if args.stage == "kf_vae":
        if args.scratch and args.parts == "decoder":
            ap.error("--parts decoder needs a trained keyframe VAE to start from; --scratch trains all of a new one")
        parts = args.parts or ("all" if args.scratch else "decoder")
        train_cfg = replace(recipe.kf_vae_train, train_parts=parts, **overrides)
        model_cfg = replace(recipe.kf_vae_model or KeyframeVAEConfig(), **weights)
        result = train_kf_vae(args.data, args.out, model_cfg, train_cfg, resume=args.resume)
    elif args.stage == "pst":
        if recipe.pst_model is None:
            ap.error(f"--recipe {args.recipe}: its 'pst' section has no 'model' (the source PST's architecture is "
                     "needed)")
        if args.kf_vae is not None and not args.scratch:
            ap.error("--kf-vae needs --scratch: a trained PST only fits the keyframe VAE it was trained on")
        if args.kf_vae is not None and not args.kf_vae.is_dir():
            ap.error(f"--kf-vae {args.kf_vae}: no such run folder")
        train_cfg = replace(recipe.pst_train, **overrides)
        # fine-tuning keeps the source PST's skip layout (a scratch PST side-canonical and without the middle pair,
        # e.g., fine-tuned again); a new one takes the recipe's unless --no-middle-skip
        source_skip = json.loads((source / "pst.json").read_text())["config"].get("middle_skip", True)
        base_skip = recipe.pst_model.middle_skip if args.scratch else source_skip
        model_cfg = replace(recipe.pst_model, side_cue=bool(args.side_cue) or recipe.pst_model.side_cue,
                            latent_norm=bool(args.latent_norm) or recipe.pst_model.latent_norm,
                            side_canonical=bool(args.side_canonical) or recipe.pst_model.side_canonical,
                            middle_skip=base_skip and not args.no_middle_skip)
        if args.no_middle_skip and not args.scratch and source_skip:
            ap.error("--no-middle-skip needs --scratch: the source PST's weights have the middle pair's projection")
        vae_path = args.kf_vae if args.kf_vae is not None else source / "kf_vae"
        result = train_pst(args.data, args.out, vae_path, model_cfg, train_cfg, text_encoder=encoder,
                           resume=args.resume)
    else:
        if args.roundtrip is not None:
            if not 0.0 <= args.roundtrip <= 1.0:
                ap.error(f"--roundtrip {args.roundtrip}: use a share in [0, 1]")
            overrides.update(keyframe_roundtrip=args.roundtrip, roundtrip_vae=str(source), keyframe_ratio=0.0)
        if args.fixed_keyframes:
            overrides.update(keyframe_ratio=0.0)
        train_cfg = replace(recipe.mmae_train, **overrides)
        model_cfg = replace(recipe.mmae_model or MMAEConfig(), **weights)
        num_keyframes = json.loads((source / "kf_vae.json").read_text())["config"].get("num_keyframes", 20)
        result = train_mmae(args.data, args.out, model_cfg, train_cfg, text_encoder=encoder, resume=args.resume,
                            num_keyframes=num_keyframes)
    print(f"{args.stage}: step {result.step}, best val {result.best_val} (step {result.best_step}), "
          f"{result.steps_per_s:.2f} steps/s -> {result.out_dir}")
    if result.interrupted:
        return 130
    if args.export is not None:
        from salad_core.keymotion.export import export_with_components

        runs = {args.stage: args.out} if args.kf_vae is None else {"kf_vae": args.kf_vae,
                                                                                   "pst": args.out}
        export_with_components(source, runs, args.export, text_encoder=text_encoder)
        print(f"pipeline with the fine-tuned {args.stage} -> {args.export}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
