#!/usr/bin/env python
"""Does KeyMotion's keyframe latent keep left and right apart, and does its PST read the side word? (issue 66,
phase 1: the latent-cache mirror check and the side probe; no training).

For test-split clips whose captions name a side and whose mirror image (``M`` + id, captions with the side
words swapped) is in the corpus:

1. **Latent mirror check.** Encode the clip's and its mirror's keyframes (the posterior means ``mu``,
   ``(Lz, Dz)``) with the keyframe VAE. ``pair / random``: the distance between a clip's latent and its
   mirror's, over the median distance between latents of unrelated clips. Near 0: the latent cannot tell a
   motion from its mirror image, so no denoiser can put the side there.
2. **Side probe.** Noise the clip's latent to ``t``, ask the PST for ``x0`` with the clip's caption and with
   the mirror's caption (the same words with left and right swapped), and project the difference on the
   mirror direction: ``side gain = <x0(caption) - x0(mirrored caption), z - z_M> / |z - z_M|^2``. A PST that
   reads the side word pulls toward the named side (gain > 0; ``1`` would be the whole step from the mirror to
   the clip). Beside it, the size of the side effect against the whole text effect:
   ``|eps(caption) - eps(mirrored)| / |eps(caption) - eps("")|``, and the same gain for another clip's caption
   in place of the mirrored one (``text gain``: how far the PST moves toward a clip for its caption at all).
3. **Canonical gain** (what a side-canonical PST, ``PSTConfig.side_canonical``, is trained for): of each pair,
   ``z_R`` is the latent whose caption names the right kind first and ``z_L`` the other; from ``x_t`` noised from
   either, ``<x0(c_R) - x0(""), z_R - z_L> / |z_R - z_L|^2`` averaged over both starts: how far the right-first
   caption pulls toward its own side beyond the unconditional prediction (0 for a PST that ignores the side).

    python lab/scripts/keymotion/keymotion_side_probe.py --data CORPUS_2.7 [--weights DIR] [--clips 64] [--out JSON]
"""
from __future__ import annotations

import argparse
import json
import re
import sys
from pathlib import Path

import numpy as np
import torch

REPO = Path(__file__).resolve().parents[3]
SIDE = re.compile(r"\b(left|right)\b", re.IGNORECASE)
TIMESTEPS = (50, 200, 400, 600, 800, 950)


def _captions(corpus: Path, mid: str) -> list[str]:
    lines = (corpus / "texts" / f"{mid}.txt").read_text(encoding="utf-8").splitlines()
    return [ln.split("#")[0].strip() for ln in lines if ln.strip()]


def _pairs(corpus: Path, n: int) -> list[tuple[str, str, str, str]]:
    """(clip id, mirror id, caption naming a side, the mirror's caption at the same line)."""
    test = [ln.strip() for ln in (corpus / "test.txt").read_text().splitlines() if ln.strip()]
    out = []
    for mid in test:
        if mid.startswith("M") or not (corpus / "new_joint_vecs" / f"M{mid}.npy").exists():
            continue
        caps, mcaps = _captions(corpus, mid), _captions(corpus, f"M{mid}")
        for c, mc in zip(caps, mcaps):
            if SIDE.search(c) and c.lower() != mc.lower():
                out.append((mid, f"M{mid}", c, mc))
                break
        if len(out) >= n:
            break
    return out


def _alphas_cumprod(cfg) -> torch.Tensor:
    betas = torch.linspace(cfg.beta_start ** 0.5, cfg.beta_end ** 0.5, cfg.num_train_timesteps, dtype=torch.float64) ** 2
    return torch.cumprod(1 - betas, 0)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--data", type=Path, required=True)
    ap.add_argument("--weights", type=Path, default=None, help="KeyMotion folder (default: the shipped one)")
    ap.add_argument("--clips", type=int, default=64)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--out", type=Path, default=None)
    args = ap.parse_args(argv)
    sys.path.insert(0, str(REPO))
    from salad_core.keymotion import KeyMotionPipeline
    from salad_core.keymotion.kf_vae import gather_keyframes
    from salad_core.keymotion.selection import select_keyframes
    from salad_core.keymotion.sides import names_left_first, side_ids_of
    from salad_core.keymotion.pst import PST_DIFFUSION

    torch.manual_seed(args.seed)
    pipe = KeyMotionPipeline.from_pretrained(args.weights)
    vae, pst = pipe.kf_vae, pipe.pst
    k, max_len = vae.num_keyframes, pipe.max_length
    pairs = _pairs(args.data, args.clips)
    if not pairs:
        raise SystemExit(f"no test clips with a side word and a mirror in {args.data}")

    def latent(mid: str) -> tuple[torch.Tensor, int]:
        feats = np.load(args.data / "new_joint_vecs" / f"{mid}.npy")[:max_len].astype(np.float32)
        x = vae.norm.normalize(torch.from_numpy(feats))[None]                     # (1, L, D)
        idx = torch.from_numpy(select_keyframes(x[0].numpy(), k, "mdo").astype(np.int64))[None]
        lens = torch.tensor([x.shape[1]])
        with torch.no_grad():
            enc = vae.encode(gather_keyframes(x, idx), vae.positions_of(idx, lens), sample=False)
        return pst.normalize_latents(enc.mu)[0], x.shape[1]

    z, zm, lens = [], [], []
    for mid, mmid, _, _ in pairs:
        a, n = latent(mid)
        b, _ = latent(mmid)
        z.append(a), zm.append(b), lens.append(n)
    z, zm = torch.stack(z), torch.stack(zm)                                       # (P, Lz, Dz)
    flat = z.flatten(1)
    pair_d = (z - zm).flatten(1).norm(dim=1)
    rand_d = torch.cdist(flat, flat)[~torch.eye(len(flat), dtype=torch.bool)]
    ratio = float(pair_d.median() / rand_d.median())

    enc = pipe.text_encoder
    tb = enc.encode([p[2] for p in pairs])
    tbm = enc.encode([p[3] for p in pairs])
    nb = enc.encode([""] * len(pairs), allow_empty=True)
    lens_t = torch.tensor(lens)
    ac = _alphas_cumprod(PST_DIFFUSION)
    cue = pst.config.side_cue
    # right-first orientation of each pair (for the canonical gain)
    right_first = torch.tensor([not names_left_first(p[2]) for p in pairs])[:, None, None]
    z_r, z_l = torch.where(right_first, z, zm), torch.where(right_first, zm, z)
    tb_r = enc.encode([p[2] if not names_left_first(p[2]) else p[3] for p in pairs])
    rows = []
    for t in TIMESTEPS:
        a = float(ac[t])
        noise = torch.randn(z.shape, generator=torch.Generator().manual_seed(args.seed + t))
        xt = (a ** 0.5) * z + ((1 - a) ** 0.5) * noise
        with torch.no_grad():
            def eps(batch):
                sides = side_ids_of(batch) if cue else None
                return pst(xt, torch.full((len(pairs),), t), batch.features, batch.mask, lens_t, sides)
            e_c, e_m, e_0 = eps(tb), eps(tbm), eps(nb)
        x0 = lambda e: (xt - ((1 - a) ** 0.5) * e) / (a ** 0.5)
        d = (z - zm).flatten(1)
        gain = ((x0(e_c) - x0(e_m)).flatten(1) * d).sum(1) / (d * d).sum(1).clamp_min(1e-12)
        share = (e_c - e_m).flatten(1).norm(dim=1) / (e_c - e_0).flatten(1).norm(dim=1).clamp_min(1e-12)
        # the same gain for another clip's caption (rolled by one): how much the PST reads the text at all
        other = torch.roll(torch.arange(len(pairs)), 1)
        with torch.no_grad():
            sides_o = side_ids_of(tb)[other] if cue else None
            e_o = pst(xt, torch.full((len(pairs),), t), tb.features[other], tb.mask[other], lens_t, sides_o)
        d_o = (z - z[other]).flatten(1)
        text_gain = ((x0(e_c) - x0(e_o)).flatten(1) * d_o).sum(1) / (d_o * d_o).sum(1).clamp_min(1e-12)
        canon = []
        for start in (z_r, z_l):
            xs = (a ** 0.5) * start + ((1 - a) ** 0.5) * noise
            with torch.no_grad():
                tt = torch.full((len(pairs),), t)
                e_r = pst(xs, tt, tb_r.features, tb_r.mask, lens_t, side_ids_of(tb_r) if cue else None)
                e_u = pst(xs, tt, nb.features, nb.mask, lens_t, side_ids_of(nb) if cue else None)
            dr = (z_r - z_l).flatten(1)
            diff = (((1 - a) ** 0.5) * (e_u - e_r) / (a ** 0.5)).flatten(1)      # x0(c_R) - x0("")
            canon.append((diff * dr).sum(1) / (dr * dr).sum(1).clamp_min(1e-12))
        canon = (canon[0] + canon[1]) / 2
        rows.append({"t": t, "canonical_gain_median": float(canon.median()),
                     "canonical_gain_positive": float((canon > 0).float().mean()), "side_gain_median": float(gain.median()), "side_gain_mean": float(gain.mean()),
                     "side_gain_positive": float((gain > 0).float().mean()),
                     "side_vs_text_effect": float(share.median()),
                     "text_gain_median": float(text_gain.median())})
    report = {"weights": str(args.weights or "shipped"), "pairs": len(pairs),
              "latent_pair_over_random_distance": ratio,
              "latent_pair_distance_median": float(pair_d.median()),
              "latent_random_distance_median": float(rand_d.median()), "probe": rows}
    print(json.dumps(report, indent=1))
    if args.out:
        args.out.parent.mkdir(parents=True, exist_ok=True)
        args.out.write_text(json.dumps(report, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
