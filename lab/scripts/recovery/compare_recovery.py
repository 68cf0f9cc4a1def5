"""Compare joint recoveries (salad_core.recovery) side by side on clean, noisy and generated features.

Three data sets (all measured with the same functions, see ``measure``):

(a) clean corpus features: recovery must not damage good motion (MPJPE to the true joints);
(b) the same features with Gaussian noise added in the normalised space (corpus Mean/Std), white
    (independent per frame) and smooth (Gaussian-filtered over time, sigma 4 frames, rescaled to
    the same std), to imitate a generator's error; MPJPE is against the clean joints;
(c) the shipped SALAD model's outputs for the prompts in ``PROMPTS`` (50 DDIM steps, w 7.5 by
    default), generated once and cached with ``--generate``.

Measures (per motion, then the mean over motions, or the max for ``*_max``; ``--json`` writes every
figure). The physical ones are ``salad_core.eval.physics.measure_motion``'s (the issue-20 benchmark's
definitions, see that module): ``bone_ref_p95_cm`` / ``bone_ref_max_cm`` (against the skeleton's
lengths), ``bone_self_max_cm`` (against the motion's own median lengths: what a fixed-bone BVH cannot
show), ``skate_mean_ms`` and ``skate_share`` (horizontal foot speed in height-based contact, PhysDiff
style, and the share above 10 cm/s), ``penetration_max_cm``, ``float_mean_cm``, ``jitter_ms3``,
``knee_hyper_max_deg``. Added here:

- ``skate_on`` (m/s): mean horizontal speed of a contact joint in frames where its predicted
  contact channel is on (> 0.5) and it is no higher than the lock heights (12 cm ankle, 6 cm toe);
- ``mpjpe`` / ``mpjpe_rel`` (cm): mean joint distance to the reference joints (the clean features'
  position recovery), global and with each frame's root subtracted.

A last table measures how well FK of the rotation features reproduces the position features (mean and
max joint distance, root-relative) on the clean corpus, the real HumanML3D sample 012314 (evaluation
only) and the generated motions.

Usage::

    OMP_NUM_THREADS=1 nice -n 10 .venv/bin/python lab/scripts/recovery/compare_recovery.py \\
        --corpus /tmp/h7_corpus --generate /tmp/h7_gen.npz     # (c) once: ~20 motions, minutes
    OMP_NUM_THREADS=1 nice -n 10 .venv/bin/python lab/scripts/recovery/compare_recovery.py \\
        --corpus /tmp/h7_corpus --generated /tmp/h7_gen.npz --json /tmp/h7_recovery.json
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np
from scipy.ndimage import gaussian_filter1d

from salad_core.eval.physics import measure_motion
from salad_core.motion import denormalize, features_to_joints, features_to_joints_rot, normalize
from salad_core.recovery import RecoveryConfig, contact_lock_mask, recover_joints
from salad_core.skeleton import get_skeleton

SK = get_skeleton("humanml3d")
FPS = SK.fps

#: Ten everyday prompts (the issue's examples among them) for the shipped model.
PROMPTS = (
    "a man is walking while raising his left hand up high",
    "a person jumps high",
    "a person walks forward",
    "a person runs forward",
    "a person kicks with the right leg",
    "a person sits down",
    "a person jogs in a circle",
    "a man waves with his right hand",
    "a person squats down and stands up",
    "a person turns around",
)

#: Recoveries compared: name -> (method, config).
VARIANTS = {
    "positions": ("positions", None),
    "fk": ("fk", RecoveryConfig()),
    "fk/no-align": ("fk", RecoveryConfig(align_heading=False)),
    "fk/motion-len": ("fk", RecoveryConfig(lengths="motion")),
    "fit/bare": ("fit", RecoveryConfig(smooth_sigma=0.0, lock_contacts=False, floor=False)),
    "fit/no-smooth": ("fit", RecoveryConfig(smooth_sigma=0.0)),
    "fit/no-lock": ("fit", RecoveryConfig(lock_contacts=False)),
    "fit/rot0.5": ("fit", RecoveryConfig(rotation_weight=0.5)),
    "fit/v0.3": ("fit", RecoveryConfig(contact_speed=0.3)),
    "fit/smooth1": ("fit", RecoveryConfig(smooth_sigma=1.0)),
    "fit": ("fit", RecoveryConfig()),
}


# =========================================================================== measures
PHYSICS = ("bone_ref_p95_cm", "bone_ref_max_cm", "bone_self_max_cm", "skate_mean_ms", "skate_share",
           "penetration_max_cm", "float_mean_cm", "jitter_ms3", "knee_hyper_max_deg")


def measure(joints: np.ndarray, features: np.ndarray, reference: np.ndarray | None = None) -> dict[str, float]:
    """Figures of one motion ``joints`` ``(N, J, 3)`` recovered from ``features`` ``(N, D)`` (see module doc)."""
    j = np.asarray(joints, dtype=np.float64)
    report = measure_motion(j, SK).as_dict()
    out = {k: float(report[k]) for k in PHYSICS}
    cj = list(SK.contact_joints)
    speed = np.linalg.norm(np.diff(j[:, cj][..., [0, 2]], axis=0), axis=-1) * FPS     # (N-1, 4)
    on = contact_lock_mask(features, j, SK, config=RecoveryConfig(min_contact_frames=1, contact_speed=None))[:-1]
    out["skate_on"] = float(speed[on].mean()) if on.any() else 0.0
    if reference is not None:
        r = np.asarray(reference, dtype=np.float64)
        out["mpjpe"] = 100 * float(np.linalg.norm(j - r, axis=-1).mean())
        out["mpjpe_rel"] = 100 * float(np.linalg.norm((j - j[:, :1]) - (r - r[:, :1]), axis=-1).mean())
    return out


def aggregate(rows: list[dict[str, float]]) -> dict[str, float]:
    """Mean over motions, except ``*_max`` figures: the max over motions."""
    out = {}
    for k in rows[0]:
        v = np.array([r[k] for r in rows], dtype=np.float64)
        v = v[np.isfinite(v)]
        out[k] = float("nan") if not v.size else float(v.max() if "_max" in k else v.mean())
    return out


def run_set(features: list[np.ndarray], references: list[np.ndarray] | None, label: str) -> dict:
    """Every variant on a list of feature arrays; prints one table, returns {variant: figures}."""
    table = {}
    for name, (method, cfg) in VARIANTS.items():
        rows, t0 = [], time.perf_counter()
        for i, f in enumerate(features):
            j = recover_joints(f, method, SK, config=cfg)
            rows.append(measure(j, f, None if references is None else references[i]))
        agg = aggregate(rows)
        agg["ms_per_motion"] = 1e3 * (time.perf_counter() - t0) / len(features)
        table[name] = agg
    print_table(table, label)
    return table


def print_table(table: dict, label: str) -> None:
    cols = list(next(iter(table.values())).keys())
    print(f"\n### {label}\n")
    print("| recovery | " + " | ".join(cols) + " |")
    print("|---|" + "---|" * len(cols))
    for name, row in table.items():
        print(f"| {name} | " + " | ".join(f"{row[c]:.3g}" for c in cols) + " |")
    sys.stdout.flush()


def fk_consistency(sets: dict[str, list[np.ndarray]]) -> dict:
    """How far FK of the rotation features (target bone lengths, official root heading) lands from
    the position features: root-relative joint distance, mean and max over each set (cm), and the
    share of motions whose max exceeds 1 cm. Prints one table."""
    table = {}
    for name, feats in sets.items():
        mean, worst = [], []
        for f in feats:
            pos = features_to_joints(f, SK)
            fk = features_to_joints_rot(f, SK)
            d = np.linalg.norm((fk - fk[:, :1]) - (pos - pos[:, :1]), axis=-1)
            mean.append(d.mean())
            worst.append(d.max())
        table[name] = {"motions": len(feats), "mean_cm": 100 * float(np.mean(mean)),
                       "max_cm": 100 * float(np.max(worst)), "share_over_1cm": float(np.mean(np.array(worst) > 0.01))}
    print_table(table, "FK of the rotation features against the position features (root-relative)")
    return table


# =========================================================================== data
def load_corpus(root: Path, limit: int | None) -> tuple[list[np.ndarray], np.ndarray, np.ndarray]:
    files = sorted((root / "new_joint_vecs").glob("*.npy"))
    if limit:
        files = files[:limit]
    if not files:
        raise SystemExit(f"no features in {root / 'new_joint_vecs'}; build a corpus with "
                         "`salad corpus build --out DIR --size tiny --seed 0`")
    feats = [np.load(p).astype(np.float64) for p in files]
    return feats, np.load(root / "Mean.npy"), np.load(root / "Std.npy")


def add_noise(features: np.ndarray, mean: np.ndarray, std: np.ndarray, sigma: float, smooth: float,
              rng: np.random.Generator) -> np.ndarray:
    """Gaussian noise of std ``sigma`` in the normalised space (temporally smoothed if ``smooth`` > 0)."""
    noise = rng.normal(size=features.shape)
    if smooth > 0:
        noise = gaussian_filter1d(noise, smooth, axis=0, mode="nearest")
        noise /= noise.std()
    return denormalize(normalize(features, mean, std) + sigma * noise, mean, std)


def generate(path: Path, steps: int, guidance: float, seeds: int, length: int) -> None:
    """Generate PROMPTS x seeds with the shipped SALAD weights and save the features to ``path``."""
    import torch

    from salad_core.pipeline import SaladPipeline

    torch.set_num_threads(1)
    pipe = SaladPipeline.from_pretrained()
    feats, names = [], []
    t0 = time.perf_counter()
    for s in range(seeds):
        out = pipe(list(PROMPTS), lengths=length, seed=1000 * s, guidance_scale=guidance, num_steps=steps)
        for b, prompt in enumerate(PROMPTS):
            feats.append(np.asarray(out.features[b][: out.lengths[b]], dtype=np.float32))
            names.append(f"{prompt} | seed {1000 * s + b}")
        print(f"seed set {s}: {time.perf_counter() - t0:.0f} s", flush=True)
    np.savez(path, features=np.stack(feats), names=np.array(names), steps=steps, guidance=guidance)
    print(f"wrote {path}: {len(feats)} motions x {length} frames ({steps} steps, w {guidance})")


# =========================================================================== main
def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--corpus", type=Path, required=True, help="corpus folder (HumanML3D layout)")
    ap.add_argument("--limit", type=int, default=None, help="use the first LIMIT clips for (a)")
    ap.add_argument("--noise-limit", type=int, default=100, help="clips for the noise sets (b)")
    ap.add_argument("--sigmas", type=float, nargs="+", default=[0.1, 0.25, 0.5])
    ap.add_argument("--generate", type=Path, default=None, help="generate (c) with the shipped model and save here")
    ap.add_argument("--generated", type=Path, default=None, help="saved generated features (c) to measure")
    ap.add_argument("--steps", type=int, default=50)
    ap.add_argument("--guidance", type=float, default=7.5)
    ap.add_argument("--seeds", type=int, default=2, help="seed sets of the ten prompts for --generate")
    ap.add_argument("--length", type=int, default=120)
    ap.add_argument("--real", type=str, default=str(Path(__file__).resolve().parents[3] / "tests" / "data"
                    / "humanml3d_sample"), help="folder with the real sample 012314 (evaluation only); '' to skip")
    ap.add_argument("--json", type=Path, default=None, help="write every table here")
    ap.add_argument("--skip", nargs="*", default=[], choices=["clean", "noise"])
    args = ap.parse_args(argv)

    if args.generate is not None:
        generate(args.generate, args.steps, args.guidance, args.seeds, args.length)
        return 0

    results: dict = {}
    feats, mean, std = load_corpus(args.corpus, args.limit)
    clean_refs = [features_to_joints(f, SK) for f in feats]
    if "clean" not in args.skip:
        results["clean"] = run_set(feats, clean_refs, f"(a) clean corpus features, {len(feats)} clips")
    if "noise" not in args.skip:
        sub = feats[: args.noise_limit]
        for smooth in (0.0, 4.0):
            for sigma in args.sigmas:
                rng = np.random.default_rng(0)
                noisy = [add_noise(f, mean, std, sigma, smooth, rng) for f in sub]
                kind = "smooth" if smooth else "white"
                results[f"noise_{kind}_{sigma}"] = run_set(
                    noisy, clean_refs[: len(sub)],
                    f"(b) {kind} noise std {sigma} (normalised space), {len(sub)} clips, MPJPE to the clean joints")
    gen = None
    if args.generated is not None:
        data = np.load(args.generated)
        gen = [f.astype(np.float64) for f in data["features"]]
        results["generated"] = run_set(
            gen, None, f"(c) shipped SALAD, {len(gen)} motions ({int(data['steps'])} DDIM steps, "
                       f"w {float(data['guidance'])})")
    real = None
    if args.real:
        path = Path(args.real) / "new_joint_vecs" / "012314.npy"
        real = np.load(path).astype(np.float64)
        results["real_012314"] = run_set([real], [features_to_joints(real, SK)],
                                         f"(a') real HumanML3D {path.stem} (evaluation only)")
    sets = {"clean corpus": feats, **({"real 012314": [real]} if real is not None else {}),
            **({"generated": gen} if args.generated is not None else {})}
    results["fk_vs_positions"] = fk_consistency(sets)
    if args.json is not None:
        args.json.write_text(json.dumps(results, indent=1))
        print(f"\nwrote {args.json}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
