"""Feet, floor and bones of VAE reconstructions, side by side for several VAEs (issue 20's skating lever).

    python lab/scripts/vae/measure_decoder_feet.py --data CORPUS [--general GENERAL] --vae salad_core/weights/salad \
        --vae ~/salad-runs/v4/dec_foot20 [--clips 60] [--perturb noise:0.5 scale:1.5]

Each ``--vae`` is a VAE run folder (``best``), an exported VAE or a pipeline folder (anything
``VAETrainConfig.init_from`` takes). The first ``--clips`` clips of each set's test split, cropped to a
multiple of 4 frames, are reconstructed (posterior mean) and turned into joints the HumanML3D way;
printed per set and VAE, with :mod:`salad_core.eval.physics`'s definitions: MPJPE (cm, root-aligned
as the official ``test_vae``), foot skating (mean m/s over the frame pairs in contact), ground penetration
(mean over clips of the max, cm), the bone-length error p95 and the worst bone (cm, max over frames and
bones), and the same measures of the clips themselves as the reference row.

``--perturb`` adds, per VAE, rows for the decoded *perturbed* posterior means (issue 20's robustness lever: the
sampler lands near, not on, the encoded latents): ``noise:S`` adds Gaussian noise of std ``S`` (in units of the
latents' own std over the clips, seeded), ``scale:F`` multiplies the latents' deviation from their mean over the
clips by ``F``. MPJPE is then against the clips, i.e. the drift the perturbation causes plus the VAE's own error.
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[3]))


def load_clips(root: Path, clips: int, unit: int = 4) -> list[np.ndarray]:
    """Raw features ``(N, 263)`` of the first ``clips`` test clips of ``root``, cropped to ``unit``."""
    ids = (root / "test.txt").read_text().split()[:clips]
    out = []
    for i in ids:
        f = np.load(root / "new_joint_vecs" / f"{i}.npy")
        out.append(f[: len(f) - len(f) % unit].astype(np.float32))
    return out


def measure(joints: list[np.ndarray], reference: list[np.ndarray] | None = None) -> dict[str, float]:
    """MPJPE against ``reference`` joints (cm, root-aligned; nan without them), skating, penetration and
    bone p95 of ``joints`` (each ``(N, 22, 3)``)."""
    from salad_core.eval.metrics import mpjpe
    from salad_core.eval.physics import bone_length_errors, foot_skating, ground_penetration, pooled_bone_p95

    skate = np.concatenate([foot_skating(j) for j in joints])
    pen = [ground_penetration(j).max() for j in joints]
    err = float("nan") if reference is None else 100 * float(np.mean([mpjpe(a, b) for a, b in zip(joints, reference)]))
    return {"mpjpe_cm": err, "skating": float(skate.mean()), "skate_share": float((skate > 0.1).mean()),
            "penetration_cm": 100 * float(np.mean(pen)), "bone_p95_cm": pooled_bone_p95(joints),
            "bone_max_cm": 100 * max(float(bone_length_errors(j)["ref_error"].max()) for j in joints)}


def parse_perturbation(spec: str) -> tuple[str, float]:
    """``"noise:0.5"`` -> ("noise", 0.5); ``"scale:1.5"`` -> ("scale", 1.5); anything else is an error."""
    kind, _, value = spec.partition(":")
    try:
        amount = float(value)
    except ValueError:
        amount = float("nan")
    if kind not in ("noise", "scale") or not np.isfinite(amount) or amount < 0:
        raise argparse.ArgumentTypeError(f"bad --perturb {spec!r}: use noise:STD or scale:FACTOR with a number >= 0")
    return kind, amount


def perturb_latents(latents: list[np.ndarray], kind: str, amount: float, seed: int = 0) -> list[np.ndarray]:
    """Perturb posterior means ``latents`` (each ``(T, P, C)`` or any shape with channels last) together:
    their mean and std per channel over all clips define the units (see the module docstring)."""
    flat = np.concatenate([z.reshape(-1, z.shape[-1]) for z in latents])
    mu, sd = flat.mean(0), flat.std(0)
    rng = np.random.default_rng(seed)
    if kind == "noise":
        return [z + amount * sd * rng.standard_normal(z.shape).astype(np.float32) for z in latents]
    return [mu + amount * (z - mu) for z in latents]


class DecoderProbe:
    """One VAE (a run, an exported VAE or a pipeline folder) loaded once, for clean and perturbed reconstructions
    of the same clips: the posterior means are encoded once and every perturbation row decodes from them."""

    def __init__(self, vae_path: str, clips: list[np.ndarray]):
        import torch

        from salad_core.io import load_model, load_tensors
        from salad_core.train.assemble import vae_source

        source = vae_source(vae_path)                     # a run (best/latest), an exported VAE or a pipeline
        self.vae = load_model(source.stem)[0].float().eval()
        stats = load_tensors(source.stats)
        self.mean, self.std = stats["mean"].numpy(), stats["std"].numpy()
        self.clips = clips
        self._latents: list[np.ndarray] | None = None

    def reconstruct(self) -> list[np.ndarray]:
        """Posterior-mean reconstructions ``(T_i, 263)`` of the clips (raw features), the batched library path."""
        import torch

        from salad_core.eval.reconstruction import reconstruct_features

        with torch.no_grad():
            return [reconstruct_features(self.vae, self.mean, self.std, f[None], [len(f)])[0] for f in self.clips]

    def latents(self) -> list[np.ndarray]:
        """The clips' posterior means ``(T_i / 4, P, C)``, encoded on first use."""
        import torch

        if self._latents is None:
            with torch.no_grad():
                self._latents = [self.vae.encode(torch.from_numpy((f - self.mean) / self.std)[None],
                                                 sample=False).z[0].numpy() for f in self.clips]
        return self._latents

    def perturbed(self, kind: str, amount: float) -> list[np.ndarray]:
        """Reconstructions ``(T_i, 263)`` from the posterior means perturbed by ``(kind, amount)``
        (``parse_perturbation``'s pair)."""
        import torch

        with torch.no_grad():
            return [self.vae.decode(torch.from_numpy(z)[None]).float()[0].numpy() * self.std + self.mean
                    for z in perturb_latents(self.latents(), kind, amount)]


def reconstruct(vae_path: str, clips: list[np.ndarray], perturbation: tuple[str, float] | None = None
                ) -> list[np.ndarray]:
    """Posterior-mean reconstructions of ``clips`` (raw features) by the VAE at ``vae_path``, the latents
    perturbed first when ``perturbation`` (``parse_perturbation``'s pair) is given."""
    probe = DecoderProbe(vae_path, clips)
    return probe.reconstruct() if perturbation is None else probe.perturbed(*perturbation)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", required=True, type=Path, help="a corpus folder (its test split)")
    ap.add_argument("--general", type=Path, default=None, help="a general-motion folder (its test split)")
    ap.add_argument("--vae", action="append", required=True, help="a VAE run, exported VAE or pipeline folder")
    ap.add_argument("--clips", type=int, default=60)
    ap.add_argument("--perturb", type=parse_perturbation, nargs="*", default=[],
                    help="extra rows per VAE: noise:STD and/or scale:FACTOR of the latents (module docstring)")
    args = ap.parse_args(argv)
    import torch

    from salad_core.motion import features_to_joints

    torch.set_num_threads(1)
    sets = {"corpus": args.data} | ({"general": args.general} if args.general else {})
    print(f"{'set':<8} {'motions':<44} {'MPJPE cm':>8} {'skating m/s':>11} {'> 0.1':>6} {'pen. cm':>7} {'bone p95':>8} {'bone max':>8}")
    for name, root in sets.items():
        clips = load_clips(root, args.clips)
        truth = [features_to_joints(f) for f in clips]
        rows = {"(the clips)": measure(truth)}
        for v in args.vae:
            probe = DecoderProbe(v, clips)
            rows[v] = measure([features_to_joints(f) for f in probe.reconstruct()], truth)
            for kind, amount in args.perturb:
                rec = probe.perturbed(kind, amount)
                rows[f"{v} {kind} {amount:g}"] = measure([features_to_joints(f) for f in rec], truth)
        for label, r in rows.items():
            print(f"{name:<8} {label[-44:]:<44} {r['mpjpe_cm']:>8.2f} {r['skating']:>11.3f} {r['skate_share']:>6.2f} "
                  f"{r['penetration_cm']:>7.2f} {r['bone_p95_cm']:>8.2f} {r['bone_max_cm']:>8.2f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
