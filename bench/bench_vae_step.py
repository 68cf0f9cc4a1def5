"""One VAE training step, the skeleto-temporal convolution's two forms side by side (issue 19).

Builds the VAE of a config (default ``configs/v2_vae.json``), then times forward + backward + AdamW on
one random batch (``--batch`` windows of ``--window`` frames) with :class:`STConv` computed as
``Conv1d`` + graph convolution (paper eq. 1 as written, the release-0.6 code) and as the single
product of :func:`salad_core.models.vae_kernels.st_conv`, interleaved in one process (A B B A ...), and
prints the median ms per step of each and their ratio. The two forms agree to float rounding (the
script checks the loss of the same batch in eval mode first).

Example::

    python bench/bench_vae_step.py --threads 1 --rounds 6
"""
from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np
import torch

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


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--config", type=Path, default=HERE / "configs" / "v2_vae.json")
    p.add_argument("--batch", type=int, default=64)
    p.add_argument("--window", type=int, default=40)
    p.add_argument("--threads", type=int, default=1)
    p.add_argument("--rounds", type=int, default=6)
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
    forms = {"conv1d + graph conv": two_branch_forward, "one product": fused_forward}

    vae.eval()
    with torch.no_grad():
        check = {}
        for name, f in forms.items():
            layers.STConv.forward = f
            check[name] = float(objective(x, eps, eps2)["loss"])
    vae.train()

    def step() -> None:
        opt.zero_grad(set_to_none=True)
        objective(x, eps, eps2)["loss"].backward()
        opt.step()

    times: dict[str, list[float]] = {name: [] for name in forms}
    names = list(forms)
    for name in names:                                  # warm-up
        layers.STConv.forward = forms[name]
        step()
    for r in range(args.rounds):
        for name in (names if r % 2 == 0 else names[::-1]):
            layers.STConv.forward = forms[name]
            t = time.perf_counter()
            step()
            step()
            times[name].append((time.perf_counter() - t) / 2)
    layers.STConv.forward = fused_forward
    med = {k: float(np.median(v)) * 1000 for k, v in times.items()}
    print(f"VAE training step, batch {args.batch} x {args.window} frames, {args.threads} thread(s), "
          f"{args.rounds} interleaved rounds; loss of one batch (eval mode): "
          + ", ".join(f"{k} {v:.6f}" for k, v in check.items()))
    for k, v in med.items():
        print(f"  {k:<20} {v:8.1f} ms/step")
    print(f"  ratio {med['conv1d + graph conv'] / med['one product']:.2f}x")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
