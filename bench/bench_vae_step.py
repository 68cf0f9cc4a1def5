"""One VAE training step, the skeleto-temporal convolution's forms side by side (issue 19).

Builds the VAE of a config (default ``lab/configs/v2_vae.json``), then times forward + backward + AdamW on
one random batch (``--batch`` windows of ``--window`` frames) with :class:`STConv` computed as

* ``conv1d + graph conv``: paper eq. 1 as written (the release-0.6 code),
* ``product, autograd``: one product of the stacked inputs with autograd's backward (pad, slices, ``cat``),
* ``product, own backward``: :func:`salad_core.models.vae_kernels.st_conv` (the same product with a
  hand-written backward), and with ``--autocast``, the same under ``torch.autocast("cpu", bfloat16)``
  (what ``TrainConfig.autocast="bf16"`` does),

interleaved in one process (the order rotated every round), and prints the median ms per step of each
and the ratios to the first. The fp32 forms agree to float rounding (the script checks the loss of the
same batch in eval mode first).

Example::

    python bench/bench_vae_step.py --threads 1 --rounds 6 --autocast
"""
from __future__ import annotations

import argparse
import contextlib
import json
import time
from pathlib import Path

import numpy as np
import torch
import torch.nn.functional as F

from salad_core.io import config_from_dict
from salad_core.models import layers
from salad_core.models.vae import MotionVAE, VAEConfig
from salad_core.train.vae_trainer import VAEObjective

HERE = Path(__file__).resolve().parents[1]


def two_branch_forward(self: layers.STConv, x: torch.Tensor) -> torch.Tensor:
    """``Conv1d`` over each joint's time series plus the graph convolution (the 0.6 form)."""
    b, n, j, c = x.shape
    t = self.temp_conv(x.permute(0, 2, 3, 1).reshape(b * j, c, n)).reshape(b, j, c, n).permute(0, 3, 1, 2)
    return t if self.graph_conv is None else t + self.graph_conv(x, self.adj_matrix)


def autograd_product_forward(self: layers.STConv, x: torch.Tensor) -> torch.Tensor:
    """The stacked product ``[h[t-1], h[t], h[t+1], A h] @ W^T`` with autograd's backward (the first
    one-product form, before the hand-written backward)."""
    b, n, j, c = x.shape
    w_t = self.temp_conv.weight
    k = w_t.shape[-1]
    pad = k // 2
    xp = F.pad(x, (0, 0, 0, 0, pad, pad))
    taps = [xp[:, i: i + n] for i in range(k)]
    weights = [w_t[:, :, i] for i in range(k)]
    bias = self.temp_conv.bias
    if self.graph_conv is not None:
        gc, adj = self.graph_conv, self.adj_matrix
        norm = adj / (adj.sum(dim=1, keepdim=True) + 1e-6)
        taps.append(torch.matmul(norm, x))
        weights[pad] = weights[pad] + gc.linear1.weight
        weights.append(gc.linear2.weight)
        bias = (bias + gc.linear1.bias)[None, :] + norm.sum(dim=1)[:, None] * gc.linear2.bias[None, :]
    return torch.cat(taps, dim=-1) @ torch.cat(weights, dim=1).t() + bias


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--config", type=Path, default=HERE / "lab" / "configs" / "v2_vae.json")
    p.add_argument("--batch", type=int, default=64)
    p.add_argument("--window", type=int, default=40)
    p.add_argument("--threads", type=int, default=1)
    p.add_argument("--rounds", type=int, default=6)
    p.add_argument("--autocast", action="store_true", help="also time the own-backward form under bf16 autocast")
    args = p.parse_args(argv)
    torch.set_num_threads(args.threads)
    torch.manual_seed(0)
    vae = MotionVAE(config_from_dict(VAEConfig, json.loads(args.config.read_text())["model"]))
    d = vae.feature_dim
    stats = (torch.zeros(d), torch.ones(d))
    objective = VAEObjective(vae, stats=stats)
    opt = torch.optim.AdamW(vae.parameters(), lr=1e-4)
    x = torch.randn(args.batch, args.window, d)
    n_lat = args.window // vae.downsample
    eps = torch.randn(args.batch, n_lat, 7, vae.config.latent_dim)
    eps2 = torch.randn_like(eps)
    fused_forward = layers.STConv.forward
    # name -> (STConv.forward, autocast dtype or None)
    forms = {"conv1d + graph conv": (two_branch_forward, None),
             "product, autograd": (autograd_product_forward, None),
             "product, own backward": (fused_forward, None)}
    if args.autocast:
        forms["own backward, bf16 autocast"] = (fused_forward, torch.bfloat16)

    def run(name: str):
        layers.STConv.forward, dtype = forms[name]
        return torch.autocast("cpu", dtype=dtype) if dtype is not None else contextlib.nullcontext()

    vae.eval()
    with torch.no_grad():
        check = {}
        for name in forms:
            with run(name):
                check[name] = float(objective(x, eps, eps2)["loss"])
    vae.train()

    def step(name: str) -> None:
        opt.zero_grad(set_to_none=True)
        with run(name):
            loss = objective(x, eps, eps2)["loss"]
        loss.backward()
        opt.step()

    times: dict[str, list[float]] = {name: [] for name in forms}
    names = list(forms)
    for name in names:                                  # warm-up
        step(name)
    for r in range(args.rounds):
        for name in names[r % len(names):] + names[: r % len(names)]:   # rotate the order every round
            t = time.perf_counter()
            step(name)
            step(name)
            times[name].append((time.perf_counter() - t) / 2)
    layers.STConv.forward = fused_forward
    med = {k: float(np.median(v)) * 1000 for k, v in times.items()}
    print(f"VAE training step ({args.config.name}), batch {args.batch} x {args.window} frames, {args.threads} "
          f"thread(s), {args.rounds} interleaved rounds; loss of one batch (eval mode): "
          + ", ".join(f"{k} {v:.6f}" for k, v in check.items()))
    first = names[0]
    for k, v in med.items():
        print(f"  {k:<28} {v:8.1f} ms/step  {med[first] / v:5.2f}x")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
