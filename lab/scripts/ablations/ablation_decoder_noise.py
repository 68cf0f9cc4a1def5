#!/usr/bin/env python
"""How much does each ablation VAE's decoder suffer from a latent that is a little off? (issue 24)

A generator's latents are never exact. If the skeleton-aware VAE's decoder turned a given latent error into a worse
motion than the pose-vector VAE's does, a denoiser on the ST latent would score a worse FID for errors of the same
relative size, and Table 3's "w/o ST-Latent" FID row would be the decoders', not the denoisers'. This scores each VAE
of the study's last VAE stage with that stage's protocol (the same crops), decoding its posterior means plus Gaussian
noise of ``k`` times the latents' spread per part and channel (the scale the denoisers normalise by), for each ``k``::

    python lab/scripts/ablations/ablation_decoder_noise.py --data CORPUS_2.4 --stage-eval salad_core/weights/ablations/evaluations/vaes@6000.json \\
        --variants st_long pose_long --noise 0 0.25 0.5 1 2 --replications 3 --out lab/records/ablations_v2/decoder_noise.json

A variant written ``NAME=RUN`` is a VAE training run instead of a shipped ablation (e.g. a probe's run, read at its
``latest`` checkpoint). The record keeps every value per
replication, the command, and the paired advantage of the first variant over each other at every ``k``.
"""
from __future__ import annotations

import argparse
import json
import shlex
import sys
from dataclasses import replace
from pathlib import Path

REPO = Path(__file__).resolve().parents[3]
sys.path.insert(0, str(REPO))
sys.path.insert(0, str(REPO / "lab"))   # salad_lab


def load_vae(spec: str):
    """``(name, vae, mean, std)`` of a shipped ablation VAE variant, or of ``NAME=RUN`` (a training run folder)."""
    from salad_lab.study import load_ablation_vae

    if "=" not in spec:
        return (spec, *load_ablation_vae(spec))
    from salad_core.io import load_model, load_tensors

    name, _, run = spec.partition("=")
    run = Path(run).expanduser()
    if not (run / "latest.safetensors").is_file():
        raise SystemExit(f"{run} holds no trained VAE run (latest.safetensors)")
    vae, _, _ = load_model(run / "latest")             # a probe is read at its last step, as it was scored
    stats = load_tensors(run / "mean_std.safetensors")
    return name, vae, stats["mean"].float().numpy(), stats["std"].float().numpy()


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--data", type=Path, required=True, help="the study's corpus")
    ap.add_argument("--stage-eval", type=Path, required=True, help="the VAE stage whose protocol is used")
    ap.add_argument("--variants", nargs="+", required=True, help="shipped ablation VAE variants, or NAME=RUN")
    ap.add_argument("--noise", nargs="+", type=float, default=[0.0, 0.25, 0.5, 1.0, 2.0],
                    help="latent noise, in units of the latents' spread")
    ap.add_argument("--replications", type=int, default=None, help="default: the stage's")
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--out", type=Path, required=True, help="the record (JSON)")
    args = ap.parse_args(argv)
    if any(k < 0 for k in args.noise):
        ap.error(f"--noise {args.noise}: shares of the latents' spread are >= 0")

    import torch

    torch.set_num_threads(args.threads)
    from salad_lab.orderings import paired_advantage
    from salad_core.eval.batches import skeleton_of
    from salad_core.eval.reconstruction import evaluate_reconstruction, latent_spread
    from salad_lab.probes import stage_settings
    from salad_core.eval.train_evaluator import load_packaged_evaluator
    from salad_core.io import atomic_write_text

    stage = json.loads(args.stage_eval.read_text())
    if stage.get("kind") != "vae":
        raise SystemExit(f"{args.stage_eval} is a {stage.get('kind')!r} stage: give a VAE stage")
    settings = stage_settings(stage, "vae")                     # the stage's protocol: the same crops
    if args.replications:
        settings = replace(settings, replications=args.replications)
    evaluator = load_packaged_evaluator()[0]
    rows = {}
    for spec in args.variants:
        name, vae, mean, std = load_vae(spec)
        spread = latent_spread(vae, mean, std, args.data, skeleton_of(evaluator), settings)
        rows[name] = {"spread_mean": float(spread.mean()), "values": {}, "summary": {}}
        for k in args.noise:
            res = evaluate_reconstruction(vae, mean, std, args.data, evaluator, settings, name=name,
                                          latent_noise=k, latent_spread=spread)
            rows[name]["values"][str(k)] = {m: list(v) for m, v in res.values.items()}
            rows[name]["summary"][str(k)] = {m: list(v) for m, v in res.summary().items()}
            s = res.summary()
            print(f"{name} k {k}: FID {s['FID'][0]:.4f} ± {s['FID'][1]:.4f}, MPJPE {100 * s['MPJPE'][0]:.2f} ± "
                  f"{100 * s['MPJPE'][1]:.2f} cm", flush=True)
    first = next(iter(rows))
    paired = {f"{first} vs {b}, k {k}, {m}": list(paired_advantage(rows[first]["values"][str(k)][m],
                                                                   rows[b]["values"][str(k)][m], m))
              for b in list(rows)[1:] for k in args.noise for m in ("FID", "MPJPE")}
    home = str(Path.home())
    command = ("python lab/scripts/ablations/ablation_decoder_noise.py " + " ".join(
        shlex.quote(str(a)) for a in (argv if argv is not None else sys.argv[1:]))).replace(home, "~")
    record = {"stage": stage["stage"], "settings": {**settings.__dict__}, "noise": args.noise, "rows": rows,
              "paired": paired, "command": command}
    args.out.parent.mkdir(parents=True, exist_ok=True)
    atomic_write_text(args.out, json.dumps(record, indent=1, default=str) + "\n")
    for key, (mean, half) in paired.items():
        print(f"{key}: {mean:+.4f} ± {half:.4f} (positive: {first} better)")
    print(f"recorded in {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
