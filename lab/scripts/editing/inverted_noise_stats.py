"""How white is the inverted noise of real takes and of procedural validation clips?

In-painting a span of a real take from fresh white noise does not do what the prompt says (a jump span of a real
take: 0 of 8), while on procedural validation clips fresh noise is the better choice (lab/docs/editing.md). One
candidate reason: the kept region's trajectory starts from the take's inverted noise, and a real take's inverted
noise may sit further from white noise than a procedural clip's. This measures it (no setting is chosen here):

Usage:
    python lab/scripts/editing/inverted_noise_stats.py [--validation 8] [--steps 50] [--frames 120] [--threads 1]
        [--json lab/records/editing/inverted_noise_stats.json]

Per motion (inverted under its prompt with ``pipe.invert``'s defaults), over its valid latent frames:
``std`` of the inverted noise z_T (white: 1), ``lag1``: the correlation of neighbouring latent frames (white: 0),
``kurtosis`` (excess; white: 0), and ``max_abs``.
"""
from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from salad_core.pipeline import SaladPipeline
from salad_core.skeleton import get_skeleton

from _measure_common import finish_run, run_settings, start_run  # scripts/
from measure_inpaint import ROOT, real_takes, tuning_takes


def noise_stats(noise: np.ndarray) -> dict:
    """``noise`` ``(N', P, Dz)`` of one motion -> its whiteness figures."""
    z = np.asarray(noise, np.float64)
    flat = z.ravel()
    a, b = z[1:].ravel(), z[:-1].ravel()
    lag1 = float(np.corrcoef(a, b)[0, 1]) if len(z) > 1 else float("nan")
    std = float(flat.std())
    kurt = float(((flat - flat.mean()) ** 4).mean() / max(std ** 4, 1e-12) - 3.0)
    return {"std": std, "lag1": lag1, "kurtosis": kurt, "max_abs": float(np.abs(flat).max())}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--validation", type=int, default=8, help="procedural validation clips")
    ap.add_argument("--steps", type=int, default=50)
    ap.add_argument("--frames", type=int, default=120)
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--json", type=Path, default=ROOT / "lab/records/editing/inverted_noise_stats.json")
    args = ap.parse_args()
    t0 = start_run(args.threads)
    pipe = SaladPipeline.from_pretrained()
    sk = get_skeleton()
    rows = []
    groups = {"real (held out)": real_takes(sk, args.frames),
              "procedural validation": tuning_takes(args.validation, args.frames)}
    rng = np.random.default_rng(0)
    for group, items in groups.items():
        for it in items:
            inv = pipe.invert(it["features"], it["prompt"], num_steps=args.steps)
            n = inv.lengths[0] // sk.unit_length
            row = {"group": group, "id": it["id"], **noise_stats(inv.noise[0, :n].cpu().numpy())}
            rows.append(row)
            print(f"{group:22s} {it['id'][:24]:24s} std {row['std']:.2f} lag1 {row['lag1']:+.2f} "
                  f"kurtosis {row['kurtosis']:+.2f} max {row['max_abs']:.1f}", flush=True)
    white = noise_stats(rng.standard_normal((args.frames // sk.unit_length, *pipe.latent_shape)))
    summary = {g: {k: float(np.mean([r[k] for r in rows if r["group"] == g])) for k in ("std", "lag1", "kurtosis",
                                                                                     "max_abs")} for g in groups}
    summary["white noise (one draw)"] = white
    print("\n| motions | std | lag-1 correlation | excess kurtosis | max abs |\n|---|---|---|---|---|")
    for g, v in summary.items():
        print(f"| {g} | {v['std']:.2f} | {v['lag1']:+.2f} | {v['kurtosis']:+.2f} | {v['max_abs']:.1f} |")
    finish_run({"settings": run_settings(args), "summary": summary, "rows": rows}, t0, args.json)


if __name__ == "__main__":
    main()
