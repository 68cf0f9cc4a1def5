"""Where KeyMotion's seed diversity goes: measured stage by stage on a trained pipeline (issue 22).

For each prompt the script samples ``--seeds`` motions and measures how far apart the seeds are at
each stage of generation, against what the same stage shows on the corpus's real motions:

* **latent**: mean pairwise L2 distance of the denoised keyframe latents ``z (Lz, Dz)`` between
  seeds, relative to the mean pairwise distance of the keyframe VAE's posterior means of real
  training windows (1.0: the seeds are as far apart as two random real motions);
* **decoder gain**: cm of keyframe-pose change per unit latent step around the samples (and around
  real latents, and real latents scaled by 2): how much latent spread the decoder can turn into pose;
* **keyframes**: mean pairwise distance (cm) of the decoded keyframe poses (each pose alone,
  root at the origin) and of their frame indices;
* **motion**: :func:`salad_core.eval.physics.seed_diversity` (cm, world coordinates, what the
  physics benchmark reports), for the MMAE's output and for plain linear interpolation of the same
  decoded keyframes (does the in-filling remove diversity?).

It also reports the noise schedule's terminal signal-to-noise ratio, with the latents' own scale
(``SNR_eff(t) = abar_t E[z^2] / (1 - abar_t)``), the posterior statistics of the keyframe VAE, and
how much of the latents' spread the decoder turns into pose spread.

Sections (``--sections``): ``schedule``, ``latents``, ``guidance`` (w sweep at DDIM 50),
``sampler`` (DDIM eta 0 / 1 and step counts at one w), ``remedies`` (guidance rescale and guidance
limited to a noise interval at that w). The corpus (``--data``) is a procedural
corpus (HumanML3D layout); never pass the real-motion evaluation sample.

Example::

    OMP_NUM_THREADS=1 nice -n 19 .venv/bin/python lab/scripts/keymotion/keymotion_diversity.py \
        --data /tmp/corpus_small --seeds 6 --out /tmp/km_div.json
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from itertools import combinations
from pathlib import Path

import numpy as np
import torch

from salad_core.eval.physics import seed_diversity
from salad_core.keymotion.kf_vae import gather_keyframes
from salad_core.keymotion.mmae import keyframe_lerp, scatter_keyframes
from salad_core.keymotion.models import pose_joints
from salad_core.keymotion.pipeline import KeyMotionPipeline, decode_keyframes
from salad_core.keymotion.pst import sample_latents
from salad_core.keymotion.sides import side_ids_of
from salad_core.keymotion.selection import select_keyframes
from salad_core.motion import features_to_joints
from salad_core.sampling import Guidance, make_scheduler

PROMPTS = ("a person walks forward", "a man is jumping high", "a man waves his right hand",
           "a person kicks with the left leg")


class EtaDDIM:
    """A DDIM scheduler whose ``step`` uses a fixed ``eta`` (0: deterministic DDIM, 1: DDPM-like)."""

    def __init__(self, scheduler, eta: float) -> None:
        self._s, self.eta = scheduler, float(eta)

    def __getattr__(self, name):
        return getattr(self._s, name)

    def step(self, model_output, timestep, sample, generator=None):
        return self._s.step(model_output, timestep, sample, eta=self.eta, generator=generator)


def mean_pairwise(x: np.ndarray) -> float:
    """Mean L2 distance between the rows of ``x (M, ...)`` over all pairs."""
    flat = x.reshape(len(x), -1)
    return float(np.mean([np.linalg.norm(flat[i] - flat[j]) for i, j in combinations(range(len(flat)), 2)]))


def mean_pose_distance(poses: np.ndarray) -> float:
    """Mean joint distance (cm) between ``poses (M, K, J, 3)`` over all pairs of the M sets."""
    return float(np.mean([np.linalg.norm(poses[i] - poses[j], axis=-1).mean()
                          for i, j in combinations(range(len(poses)), 2)]) * 100.0)


def decoder_gain(vae, z: np.ndarray, step: float = 0.5, repeats: int = 4) -> float:
    """How much the keyframe decoder moves the poses per unit of latent: mean joint displacement (cm)
    of the decoded keyframes for random latent steps of norm ``step``, divided by ``step``
    (``z (M, Lz, Dz)``; a small value means the decoder is saturated there)."""
    zt = torch.as_tensor(z, dtype=torch.float32)
    rs = torch.Generator().manual_seed(5)
    den = vae.norm.denormalize
    with torch.no_grad():
        base = pose_joints(den(vae.decode(zt).keyframes), vae.skeleton)
        out = []
        for _ in range(repeats):
            d = torch.randn(zt.shape, generator=rs)
            d = d / d.flatten(1).norm(dim=1)[:, None, None] * step
            moved = pose_joints(den(vae.decode(zt + d).keyframes), vae.skeleton)
            out.append(float((moved - base).norm(dim=-1).mean()) * 100.0 / step)
    return float(np.mean(out))


def schedule_section(pipe: KeyMotionPipeline, z_second_moment: float) -> dict:
    """Terminal SNR of the PST's schedule, nominal and with the latents' scale."""
    sched = make_scheduler(pipe.diffusion, pipe.solver)
    abar = sched.alphas_cumprod.double()
    sched.set_timesteps(50)
    first = int(sched.timesteps[0])
    out = {}
    for name, t in (("t_999", 999), (f"first_ddim50_t_{first}", first)):
        a = float(abar[t])
        out[name] = {"abar": a, "snr": a / (1 - a), "snr_eff": a * z_second_moment / (1 - a),
                     "signal_share_of_std": float(np.sqrt(a * z_second_moment) /
                                                  np.sqrt(a * z_second_moment + 1 - a))}
    return out


def data_latents(pipe: KeyMotionPipeline, data: Path, split: str, limit: int, rng: np.random.Generator) -> dict:
    """Posterior of the keyframe VAE on ``limit`` real windows (<= max_length frames) of ``split``."""
    from salad_core.data.dataset import MotionTextDataset

    vae = pipe.kf_vae
    ds = MotionTextDataset(data, split, max_length=vae.config.max_length, random_crop=False,
                           mean=vae.norm.mean.numpy(), std=vae.norm.std.numpy())
    pick = rng.choice(len(ds), size=min(limit, len(ds)), replace=False)
    mus, sig, kf_true, kf_dec, captions = [], [], [], [], []
    k = vae.config.num_keyframes
    for i in pick:
        item = ds[int(i)]
        n = int(item["length"])
        if n < k:
            continue
        x = torch.as_tensor(item["motion"][:n], dtype=torch.float32)[None]
        idx = torch.from_numpy(select_keyframes(x[0].numpy(), k, "mdo"))[None]
        kfs = gather_keyframes(x, idx)
        with torch.no_grad():
            enc = vae.encode(kfs, vae.positions_of(idx, torch.tensor([n])), sample=False)
            dec = vae.decode(enc.mu)
        mus.append(enc.mu[0].numpy())
        sig.append(torch.exp(0.5 * enc.logvar[0]).numpy())
        kf_true.append(pose_joints(vae.norm.denormalize(kfs), vae.skeleton)[0].numpy())
        kf_dec.append(pose_joints(vae.norm.denormalize(dec.keyframes), vae.skeleton)[0].numpy())
        captions.append(item["caption"])
    mu = np.stack(mus)
    sd = np.stack(sig)
    return {"mu": mu, "sigma": sd, "kf_true": np.stack(kf_true), "kf_dec": np.stack(kf_dec), "captions": captions}


def latents_section(lat: dict, vae) -> dict:
    mu, sd = lat["mu"], lat["sigma"]
    flat = mu.reshape(len(mu), -1)
    m = min(len(mu), 40)
    return {
        "windows": int(len(mu)),
        "mu_rms": float(np.sqrt((flat ** 2).mean())),
        "mu_between_clip_std": float(flat.std(0).mean()),       # per element, averaged
        "posterior_sigma_mean": float(sd.mean()),
        "z_second_moment": float((flat ** 2).mean() + (sd ** 2).mean()),
        "mu_pairwise_l2": mean_pairwise(mu[:m]),
        "mu_nn_l2": float(np.mean([np.sort(np.linalg.norm(flat - flat[i], axis=1))[1] for i in range(m)])),
        "keyframe_pose_pairwise_cm_true": mean_pose_distance(lat["kf_true"][:m]),
        "keyframe_pose_pairwise_cm_decoded_mu": mean_pose_distance(lat["kf_dec"][:m]),
        "decoder_gain_cm": decoder_gain(vae, mu),
        "decoder_gain_cm_at_2x": decoder_gain(vae, 2.0 * mu),
    }


def generate(pipe: KeyMotionPipeline, prompt: str, seeds: list[int], length: int, w: "float | Guidance", steps: int,
             scheduler_factory) -> dict:
    """Sample ``len(seeds)`` motions of one prompt; the stages' outputs (numpy)."""
    b = len(seeds)
    tb = pipe.text_encoder.encode([prompt])
    text, mask = tb.features.expand(b, -1, -1), tb.mask.expand(b, -1)
    nb = pipe.text_encoder.encode([""], allow_empty=True)
    lz, dz = pipe.pst.config.latent_size, pipe.pst.config.latent_dim
    noise = torch.stack([torch.randn((lz, dz), generator=torch.Generator().manual_seed(s)) for s in seeds])
    len_t = torch.full((b,), length, dtype=torch.long)
    sides = side_ids_of(tb).expand(b, -1) if pipe.pst.config.side_cue else None     # a side-cue PST reads them
    z = sample_latents(pipe.pst, scheduler_factory(), text, mask, nb.features, nb.mask, noise, lengths=len_t,
                       guidance_scale=w, num_steps=steps, generator=torch.Generator().manual_seed(seeds[0]),
                       text_sides=sides)
    with torch.inference_mode():
        kfs, idx = decode_keyframes(pipe.kf_vae, z, len_t)
        motion = pipe.mmae.infill(kfs, idx, len_t, text, mask)
        canvas, kf_mask = scatter_keyframes(kfs, idx, length)
        lerp = keyframe_lerp(canvas, kf_mask)
        den = pipe.mmae.norm.denormalize
        poses = pose_joints(den(kfs), pipe.skeleton).numpy()
        feats, lfeats = den(motion).numpy(), den(lerp).numpy()
    joints = [features_to_joints(f, pipe.skeleton) for f in feats]
    ljoints = [features_to_joints(f, pipe.skeleton) for f in lfeats]
    travel = [float(np.linalg.norm(j[-1, 0, [0, 2]] - j[0, 0, [0, 2]])) for j in joints]
    return {"z": z.numpy(), "poses": poses, "indices": idx.numpy(), "joints": joints, "lerp_joints": ljoints,
            "travel": travel}


def spread(out: dict, lat: dict, ls: dict, vae) -> dict:
    """The seeds' spread at each stage, and how far their latents lie from the real ones."""
    rel = [j - j[:, :1] for j in out["joints"]]                 # root-relative: pose only, no trajectory
    z = out["z"].reshape(len(out["z"]), -1)
    mu = lat["mu"].reshape(len(lat["mu"]), -1)
    nearest = np.sqrt(((z[:, None] - mu[None]) ** 2).sum(-1)).min(1)
    return {
        "latent_rel": mean_pairwise(out["z"]) / ls["mu_pairwise_l2"],
        "z_rms_rel": float(np.sqrt((z ** 2).mean()) / ls["mu_rms"]),       # 1: the scale of real latents
        "nearest_real_rel": float(nearest.mean() / ls["mu_nn_l2"]),          # 1: as close as real ones are
        "decoder_gain_cm": decoder_gain(vae, out["z"]),
        "keyframe_pose_cm": mean_pose_distance(out["poses"]),
        "keyframe_index_frames": float(np.mean([np.abs(out["indices"][i] - out["indices"][j]).mean()
                                                for i, j in combinations(range(len(out["z"])), 2)])),
        "motion_cm": seed_diversity(out["joints"]),
        "motion_root_relative_cm": seed_diversity(rel),
        "lerp_motion_cm": seed_diversity(out["lerp_joints"]),
        "travel_m_mean": float(np.mean(out["travel"])),
    }


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--weights", default=None, help="KeyMotion pipeline folder or training root (default: shipped)")
    ap.add_argument("--data", required=True, help="procedural corpus (HumanML3D layout) for the latent statistics")
    ap.add_argument("--split", default="train")
    ap.add_argument("--windows", type=int, default=200, help="real windows for the latent statistics")
    ap.add_argument("--prompts", nargs="*", default=list(PROMPTS))
    ap.add_argument("--seeds", type=int, default=6)
    ap.add_argument("--length", type=int, default=100)
    ap.add_argument("--guidance", type=float, nargs="*", default=[1.0, 2.5, 5.0, 7.5])
    ap.add_argument("--sampler-w", type=float, default=7.5, help="guidance weight of the sampler section")
    ap.add_argument("--sections", nargs="*", default=["schedule", "latents", "guidance", "sampler", "remedies"])
    ap.add_argument("--out", default=None, help="write the figures as JSON here")
    args = ap.parse_args(argv)
    torch.set_num_threads(1)
    pipe = KeyMotionPipeline.from_pretrained(args.weights)
    rng = np.random.default_rng(0)
    t0 = time.time()
    lat = data_latents(pipe, Path(args.data), args.split, args.windows, rng)
    ls = latents_section(lat, pipe.kf_vae)
    report: dict = {"weights": args.weights or "shipped", "data": args.data, "length": args.length,
                    "seeds": args.seeds, "latents": ls}
    if "schedule" in args.sections:
        report["schedule"] = schedule_section(pipe, ls["z_second_moment"])
    seeds = list(range(args.seeds))
    ddim = lambda eta=0.0: (lambda: EtaDDIM(make_scheduler(pipe.diffusion, "ddim"), eta))  # noqa: E731
    rows = []

    def run(section: str, label: str, w: "float | Guidance", steps: int, factory) -> None:
        for p in args.prompts:
            s = spread(generate(pipe, p, seeds, args.length, w, steps, factory), lat, ls, pipe.kf_vae)
            wd = w.scale if isinstance(w, Guidance) else w
            rows.append({"section": section, "setting": label, "w": wd, "steps": steps, "prompt": p, **s})
            print(json.dumps(rows[-1]), flush=True)

    if "guidance" in args.sections:
        for w in args.guidance:
            run("guidance", f"ddim50 w={w}", w, 50, ddim(0.0))
    if "sampler" in args.sections:
        w = args.sampler_w
        for label, steps, fac in (("ddim10 eta0", 10, ddim(0.0)), ("ddim50 eta1", 50, ddim(1.0)),
                                  ("ddim200 eta0", 200, ddim(0.0))):
            run("sampler", f"{label} w={w}", w, steps, fac)
    if "remedies" in args.sections:
        w = args.sampler_w
        for label, g in ((f"rescale0.7 w={w}", Guidance(w, rescale=0.7)),
                         (f"interval(0,0.5) w={w}", Guidance(w, interval=(0.0, 0.5))),
                         (f"interval(0.1,0.7) w={w}", Guidance(w, interval=(0.1, 0.7)))):
            run("remedies", label, g, 50, ddim(0.0))
    report["rows"] = rows
    # one line per setting: means over prompts
    keys = ("latent_rel", "z_rms_rel", "nearest_real_rel", "decoder_gain_cm", "keyframe_pose_cm",
            "keyframe_index_frames", "motion_cm", "motion_root_relative_cm",
            "lerp_motion_cm", "travel_m_mean")
    summary = {}
    for r in rows:
        summary.setdefault(r["setting"], []).append(r)
    report["summary"] = {k: {f: float(np.mean([r[f] for r in v])) for f in keys} for k, v in summary.items()}
    report["seconds"] = time.time() - t0
    print(json.dumps({"latents": ls, "schedule": report.get("schedule")}, indent=1))
    print("| setting | " + " | ".join(keys) + " |")
    print("|---" * (len(keys) + 1) + "|")
    for k, v in report["summary"].items():
        print(f"| {k} | " + " | ".join(f"{v[f]:.3g}" for f in keys) + " |")
    if args.out:
        Path(args.out).write_text(json.dumps(report, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
