#!/usr/bin/env python
"""Do the ablation study's denoisers denoise differently? Their x0 estimate at each noise level (issue 24).

Table 3's x/v row and the ST latent's FID row are level in our study where the paper has the full model ahead. Two
denoisers whose estimates of the clean latent are equally good at every timestep make the same motions, whatever
they predict; this measures those estimates (:mod:`salad_core.eval.denoising_error`) on the test crops of the
stage's protocol (its first replication), for each shipped denoiser variant, with the same noise on the same clips
(paired), conditional and guided at the stage's weight::

    python lab/scripts/ablations/ablation_denoising_error.py --data CORPUS_2.4 --stage-eval salad_core/weights/ablations/evaluations/denoisers@8000.json \\
        --variants full x0 eps no_st no_cross no_both no_film --out lab/records/ablations_v2/denoising_error.json

The record keeps each variant's mean per timestep (latent MSE in the normalised latent space, decoded joint error in
metres against the decoded clean latent) and each variant's paired difference from the first (positive: the first
is better), with 95 % half-widths; the latent MSE is compared only between variants on the same VAE. It also keeps
the FID (the shipped evaluator) of the motions decoded from each one-step estimate, per timestep, beside the FID of
the decoded clean latents: at t = 0 that is what the sampler's last step does to a finished motion.
``--unconditional`` adds the empty prompt's estimate (the branch guidance extrapolates away from)::

    python lab/scripts/ablations/ablation_denoising_error.py --data CORPUS_2.4 --stage-eval salad_core/weights/ablations/evaluations/denoisers@8000.json \\
        --variants full no_st --unconditional --out lab/records/ablations_v2/denoising_error_unconditional.json
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


def run_pipeline(run: Path):
    """The pipeline of a denoiser run's ``latest`` checkpoint with the VAE the run records, assembled in fp16 as the
    study's rows were (``salad_lab.probes`` scores probes the same way)."""
    import tempfile

    from salad_lab.probes import assemble_latest
    from salad_core.pipeline import SaladPipeline

    if not (run / "latest.safetensors").is_file():
        raise SystemExit(f"{run} holds no denoiser run (latest.safetensors)")
    with tempfile.TemporaryDirectory() as tmp:
        return SaladPipeline.from_pretrained(assemble_latest(run, None, tmp))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--data", type=Path, required=True, help="the study's corpus")
    ap.add_argument("--stage-eval", type=Path, required=True, help="the denoiser stage whose protocol is used")
    ap.add_argument("--variants", nargs="+", required=True, help="shipped denoiser ablations, or NAME=RUN for a "
                    "denoiser training run (a probe's; read at its latest checkpoint with the VAE it records, fp16 "
                    "as the study's rows); the first is the base")
    ap.add_argument("--weights", type=Path, default=None, help="their folder (default: salad_core/weights/ablations)")
    ap.add_argument("--timesteps", nargs="+", type=int, default=None, help="default: DEFAULT_TIMESTEPS")
    ap.add_argument("--batches", type=int, default=None, help="only the first N batches of the crops (default: all)")
    ap.add_argument("--unconditional", action="store_true", help="also the empty prompt's estimate (mode 'uncond': "
                    "the branch guidance extrapolates away from)")
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--out", type=Path, required=True, help="the record (JSON)")
    args = ap.parse_args(argv)
    if len(set(args.variants)) != len(args.variants):
        ap.error(f"--variants {args.variants}: each once")

    import torch

    torch.set_num_threads(args.threads)
    from salad_lab.probes import stage_settings
    from salad_lab.denoising import denoising_markdown, summarise
    from salad_lab.study import load_ablation_pipeline
    from salad_core.eval.batches import batches_for, evaluation_dataset
    from salad_core.eval.denoising_error import DEFAULT_TIMESTEPS, denoising_error
    from salad_core.eval.train_evaluator import load_packaged_evaluator
    from salad_core.io import atomic_write_text

    stage = json.loads(args.stage_eval.read_text())
    settings = stage_settings(stage, "denoiser")
    missing = [v for v in args.variants if "=" not in v and v not in stage["rows"]]
    if missing:
        raise SystemExit(f"{missing} are not rows of {args.stage_eval} ({sorted(stage['rows'])})")
    timesteps = tuple(args.timesteps or DEFAULT_TIMESTEPS)
    evaluator = load_packaged_evaluator()[0]
    results, clips = {}, None
    first = args.variants[0].partition("=")[0]
    for spec in args.variants:
        name, _, run = spec.partition("=")
        pipe = load_ablation_pipeline(name, args.weights) if not run else run_pipeline(Path(run).expanduser())
        ds = evaluation_dataset(args.data, settings, pipe.skeleton)
        batches = batches_for(ds, settings, 0, 0)[: args.batches]
        r = denoising_error(pipe, batches, timesteps=timesteps, guidance_scale=settings.guidance_scale,
                            noise_seed=settings.seed, evaluator=evaluator, unconditional=args.unconditional)
        if clips is not None and r.clips != clips:
            raise SystemExit(f"{name} was measured on other clips than {first}: not paired")
        clips = r.clips
        results[name] = r
        print(f"{name}: {len(r.clips)} clips, {r.prediction_type}", flush=True)
    record = {"what": "each denoiser's estimate of the clean latent at each timestep, on the stage's test crops "
                      "(first replication), the same noise per clip for denoisers of the same latent shape",
              "stage": stage["stage"], "steps": stage["steps"], "guidance_scale": settings.guidance_scale,
              "clips": len(clips), "timesteps": list(timesteps), "first": first,
              "modes": ["cond"] + ["uncond"] * args.unconditional + ["guided"],
              "variants": summarise(results, first),
              "command": "python lab/scripts/ablations/ablation_denoising_error.py " + " ".join(
                  shlex.quote(str(a)) for a in (argv if argv is not None else sys.argv[1:])).replace(str(Path.home()), "~")}
    record = json.loads(json.dumps(record, default=float))      # int timestep keys -> strings, as read back
    atomic_write_text(args.out, json.dumps(record, indent=1) + "\n")
    for metric in ("fid", "joints", "latent"):
        for mode in ("cond",) + ("uncond",) * args.unconditional + ("guided",):
            print(denoising_markdown(record, metric, mode) + "\n")
    print(f"recorded in {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
