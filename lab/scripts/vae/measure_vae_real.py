"""EVALUATION ONLY: how well a VAE reconstructs real motion capture (and the procedural sets).

Usage::

    python lab/scripts/vae/measure_vae_real.py [--vae DIR] [--corpus CORPUS] [--general GENERAL] [--json OUT.json]
    python lab/scripts/vae/measure_vae_real.py --stats --corpus CORPUS --general GENERAL     # feature ranges

``--vae`` is a pipeline folder (``vae.*`` + ``stats.safetensors``, default: the shipped weights
``salad_core/weights/salad``) or a VAE training run (``best.*`` or ``latest.*`` +
``mean_std.safetensors``). Every clip is encoded and decoded with the posterior mean at its own
length (floored to a multiple of 4, at most 196 frames) and compared in joint space:

* root-aligned MPJPE (each pose's pelvis subtracted; the VAE-paper metric),
* global MPJPE (no alignment: errors of the integrated root path count too),
* the yaw drift: the largest error of the heading integrated from the root's angular velocity
  (degrees; issue 21 found it drives the root-aligned error on turning clips),
* the local pose error: mean distance of the ``ric`` features (root-relative joints in the heading
  frame, cm), which no root drift touches, and
* per set, how well the decoder reproduces the root channels (rms, correlation and R^2 of the
  angular velocity, also summed per latent frame; :func:`root_channel_stats`),

all against ``features_to_joints`` (and the features) of the clip itself, MPJPE in cm; per clip and median / max
per set. Sets: the real HumanML3D sample (``tests/data/humanml3d_sample``, clip 012314), pybullet's
DeepMimic clips with at least 40 feature rows (looping clips repeated to reach them, as
``lab/scripts/editing/measure_editing.py`` does; converted by :mod:`salad_core.data.deepmimic`; skipped
with a note when pybullet is not installed), and the test splits of ``--corpus`` and ``--general``.

The real clips (012314 and DeepMimic) are evaluation data: never choose generator parameters, the
mixture ratio or training settings by looking at these figures; choose them on held-out procedural
clips (``--general``'s test split) and coverage arguments, and only report the real figures.

``--stats`` instead prints how far the general set's features fall outside the corpus's (the
share of values beyond the corpus training split's per-dimension range, and percentiles of
``|x - mean| / std`` under the corpus's Mean/Std) -- the measurement behind the mixture's
normalisation choice.
"""
from __future__ import annotations

import argparse
import contextlib
import json
import os
import sys
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[3]
SAMPLE = REPO / "tests" / "data" / "humanml3d_sample"
#: Shortest clip measured (feature rows): HumanML3D's minimum motion length.
MIN_ROWS = 40


def load_vae(path: str | Path | None):
    """``(vae, mean, std, description)`` from a pipeline folder, an exported VAE folder, a VAE training run or a
    checkpoint stem in one (:func:`salad_core.train.assemble.vae_source`); the shipped pipeline by default."""
    from salad_core.io import load_model, load_tensors
    from salad_core.pipeline import default_weights_dir
    from salad_core.train.assemble import vae_source

    source = vae_source(Path(path) if path is not None else default_weights_dir())
    if not source.has_stats:
        raise FileNotFoundError(f"--vae {path}: no {source.stats.name} beside {source.stem} (the Mean/Std the VAE "
                                "was trained with)")
    vae, _, _ = load_model(source.stem)
    stats = load_tensors(source.stats)
    return vae, stats["mean"].numpy(), stats["std"].numpy(), f"{source.stem} ({source.stats.name})"


def _crop(feats: np.ndarray, unit: int = 4, max_len: int = 196) -> np.ndarray:
    n = min(len(feats) - len(feats) % unit, max_len)
    return feats[:n]


def measure_clip(vae, mean, std, feats: np.ndarray, pairs: list | None = None, sample: bool = False) -> dict:
    """Root-aligned and global MPJPE (cm) of one clip's posterior-mean reconstruction.

    ``pairs``, when given, receives ``(reconstruction, clip)`` (both ``(N, D)`` raw features, the clip
    cropped as measured) for :func:`root_channel_stats`. ``sample`` decodes a posterior sample
    (``mu + eps * sigma``, seed 0) instead of the mean.
    """
    from salad_core.eval.metrics import mpjpe
    from salad_core.eval.reconstruction import reconstruct_features
    from salad_core.motion import features_to_joints

    f = _crop(np.asarray(feats, dtype=np.float32), int(vae.config.downsample))
    rec = reconstruct_features(vae, mean, std, f[None], [len(f)], sample=sample)[0]
    if pairs is not None:
        pairs.append((rec, f))
    gt, pr = features_to_joints(f.astype(np.float64)), features_to_joints(rec.astype(np.float64))
    return {"frames": len(f), "mpjpe_cm": 100 * mpjpe(pr, gt, root_aligned=True),
            "global_cm": 100 * mpjpe(pr, gt, root_aligned=False),
            "yaw_drift_deg": yaw_drift_deg(rec, f), "ric_cm": ric_error_cm(rec, f)}


def ric_error_cm(rec: np.ndarray, feats: np.ndarray) -> float:
    """Mean distance (cm) between the ``ric`` features of the reconstruction and the clip: the local
    pose (root-relative joints in the heading frame), untouched by any root drift."""
    from salad_core.skeleton import get_skeleton

    sl = get_skeleton("humanml3d").feature_slices["ric"]
    d = (np.asarray(rec, np.float64)[:, sl] - np.asarray(feats, np.float64)[:, sl]).reshape(len(rec), -1, 3)
    return float(100 * np.linalg.norm(d, axis=-1).mean())


#: The root channels of HumanML3D-layout features (columns 0-3).
ROOT_CHANNELS = ("rot_vel", "vel_x", "vel_z", "root_y")


def root_channel_stats(pairs: list[tuple[np.ndarray, np.ndarray]], unit: int = 4) -> dict:
    """How well a set's reconstructions reproduce the root channels (issue 21: the decoder all but
    dropped the angular velocity).

    Parameters
    ----------
    pairs : list of ``(reconstruction, clip)``
        Raw features ``(N, D)`` of each clip, ``N`` a multiple of ``unit``.
    unit : int
        Frames per latent frame: ``rot_vel_latent`` sums the angular velocity over each latent
        frame's ``unit`` rows (the yaw change per latent frame, what the heading integrates).

    Returns
    -------
    dict
        ``{channel: {"rms_true", "rms_rec", "corr", "r2"}}`` over all frames of the set (radians
        or metres per frame; ``root_y`` metres), for the four root channels and ``rot_vel_latent``.
    """
    rec = np.concatenate([r for r, _ in pairs]).astype(np.float64)
    ref = np.concatenate([f for _, f in pairs]).astype(np.float64)
    cols = {name: (rec[:, i], ref[:, i]) for i, name in enumerate(ROOT_CHANNELS)}
    per_latent = lambda a: a.reshape(-1, unit).sum(1)                       # clips are whole latent frames
    cols["rot_vel_latent"] = (per_latent(rec[:, 0]), per_latent(ref[:, 0]))
    out = {}
    for name, (r, t) in cols.items():
        var = ((t - t.mean()) ** 2).sum()
        out[name] = {"rms_true": float(np.sqrt((t ** 2).mean())), "rms_rec": float(np.sqrt((r ** 2).mean())),
                     "corr": float(np.corrcoef(r, t)[0, 1]) if r.std() > 0 and t.std() > 0 else float("nan"),
                     "r2": float(1 - ((t - r) ** 2).sum() / var) if var > 0 else float("nan")}
    return out


def yaw_drift_deg(rec: np.ndarray, feats: np.ndarray) -> float:
    """Largest heading error (degrees) over a clip: the root yaw integrated from the angular-velocity
    channel (HumanML3D's ``recover_root_rot_pos``: twice the summed half-angles of the rows before
    each frame) of the reconstruction against the clip's own (issue 21: it dominates the error)."""
    def yaw(f):
        f = np.asarray(f, dtype=np.float64)
        return 2.0 * np.concatenate([[0.0], np.cumsum(f[:-1, 0])])
    return float(np.degrees(np.abs(yaw(rec) - yaw(feats)).max()))


@contextlib.contextmanager
def _quiet_stdout():
    """Silence C-level prints to fd 1 (pybullet's URDF loader warns about every joint)."""
    sys.stdout.flush()
    saved = os.dup(1)
    try:
        with open(os.devnull, "w") as null:
            os.dup2(null.fileno(), 1)
            yield
    finally:
        os.dup2(saved, 1)
        os.close(saved)


def real_clips(rig: str = "smpl") -> tuple[dict[str, dict[str, np.ndarray]], list[str]]:
    """``({set: {clip: features}}, notes)`` of the real evaluation clips available here; the DeepMimic clips on
    the torso geometry ``rig`` (:data:`salad_core.data.deepmimic.RIGS`: HumanML3D's by default)."""
    notes = []
    sets = {"humanml3d_012314": {"012314": np.load(SAMPLE / "new_joint_vecs" / "012314.npy")}}
    from salad_core.data import deepmimic

    if not deepmimic.pybullet_available():
        notes.append("DeepMimic skipped: pybullet (extra 'deepmimic') is not installed")
        return sets, notes
    dm = {}
    for name in deepmimic.available_clips():
        with _quiet_stdout():
            clip = deepmimic.load_clip(name, rig=rig)
        if clip.loop and clip.num_frames - 1 < MIN_ROWS:      # cycles are repeated, as for editing
            cycles = int(np.ceil(MIN_ROWS / max(clip.num_frames - 1, 1))) + 1
            with _quiet_stdout():
                clip = deepmimic.load_clip(name, cycles=cycles, rig=rig)
            name = f"{name} (x{cycles})"
        feats = clip.features()
        if len(feats) >= MIN_ROWS:
            dm[name] = feats
        else:
            notes.append(f"DeepMimic {name}: {len(feats)} feature rows < {MIN_ROWS} and not a loop, left out")
    sets["deepmimic"] = dm
    return sets, notes


def split_clips(root: Path, split: str = "test", limit: int | None = None) -> dict[str, np.ndarray]:
    ids = [x for x in (root / f"{split}.txt").read_text().split() if x][:limit]
    out = {}
    for i in ids:
        f = np.load(root / "new_joint_vecs" / f"{i}.npy")
        if len(f) >= 8:
            out[i] = f
    return out


def summarise(rows: dict[str, dict]) -> dict:
    a = np.array([r["mpjpe_cm"] for r in rows.values()])
    g = np.array([r["global_cm"] for r in rows.values()])
    y = np.array([r["yaw_drift_deg"] for r in rows.values()])
    c = np.array([r["ric_cm"] for r in rows.values()])
    return {"clips": len(rows), "mpjpe_median_cm": float(np.median(a)), "mpjpe_max_cm": float(a.max()),
            "global_median_cm": float(np.median(g)), "global_max_cm": float(g.max()),
            "yaw_drift_median_deg": float(np.median(y)), "yaw_drift_max_deg": float(y.max()),
            "ric_median_cm": float(np.median(c)), "ric_mean_cm": float(c.mean())}


def feature_stats(corpus: Path, general: Path, limit: int | None = None) -> dict:
    """How far the general set's features leave the corpus's ranges (see the module notes)."""
    from salad_core.skeleton import get_skeleton

    sk = get_skeleton("humanml3d")
    mean, std = np.load(corpus / "Mean.npy"), np.load(corpus / "Std.npy")
    cor = np.concatenate(list(split_clips(corpus, "train", limit).values()))
    gen = np.concatenate(list(split_clips(general, "train", limit).values()))
    lo, hi = cor.min(0), cor.max(0)
    out = {"corpus_rows": len(cor), "general_rows": len(gen), "blocks": {}}
    for name, sl in sk.feature_slices.items():
        zc = np.abs(cor[:, sl] - mean[sl]) / std[sl]
        zg = np.abs(gen[:, sl] - mean[sl]) / std[sl]
        outside = ((gen[:, sl] < lo[sl]) | (gen[:, sl] > hi[sl])).mean()
        out["blocks"][name] = {"general_outside_corpus_range": float(outside),
                               "z_p99_corpus": float(np.percentile(zc, 99)), "z_p99_general": float(np.percentile(zg, 99)),
                               "z_max_general": float(zg.max()),
                               "std_ratio_general_over_corpus": float(np.median(gen[:, sl].std(0) / np.maximum(cor[:, sl].std(0), 1e-6)))}
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--vae", default=None, help="pipeline folder or VAE run (default: the shipped weights)")
    ap.add_argument("--corpus", type=Path, default=None, help="procedural corpus: its test split is measured too")
    ap.add_argument("--general", type=Path, default=None, help="general-motion set: its test split is measured too")
    ap.add_argument("--limit", type=int, default=200, help="clips per procedural test split (default 200)")
    ap.add_argument("--json", type=Path, default=None, help="write every figure to this JSON file")
    ap.add_argument("--sample", action="store_true",
                    help="decode posterior samples mu + eps * sigma (seed 0) instead of the mean: how the decoder "
                         "treats latents as noisy as a denoiser's training targets")
    ap.add_argument("--deepmimic-rig", choices=("smpl", "deepmimic"), default="smpl",
                    help="torso geometry of the converted DeepMimic clips: HumanML3D's (default) or the humanoid's own "
                         "level hips and straight spine (the conversion before session 10; salad_core.data.deepmimic)")
    ap.add_argument("--stats", action="store_true", help="print feature-range figures instead (needs --corpus, --general)")
    args = ap.parse_args(argv)

    if args.stats:
        if args.corpus is None or args.general is None:
            ap.error("--stats needs --corpus and --general")
        res = feature_stats(args.corpus, args.general, args.limit * 10)
        print(f"{'block':14s} {'outside corpus range':>21s} {'|z| p99 corpus':>15s} {'|z| p99 general':>16s} "
              f"{'|z| max general':>16s} {'std ratio':>10s}")
        for name, b in res["blocks"].items():
            print(f"{name:14s} {b['general_outside_corpus_range']:21.3f} {b['z_p99_corpus']:15.2f} "
                  f"{b['z_p99_general']:16.2f} {b['z_max_general']:16.1f} {b['std_ratio_general_over_corpus']:10.2f}")
        if args.json:
            args.json.write_text(json.dumps(res, indent=2) + "\n")
        return 0

    import torch

    torch.set_grad_enabled(False)
    vae, mean, std, desc = load_vae(args.vae)
    print(f"VAE: {desc}; decoding the {'posterior samples (seed 0)' if args.sample else 'posterior mean'}; "
          f"DeepMimic clips on the {args.deepmimic_rig} torso")
    sets, notes = real_clips(args.deepmimic_rig)
    if args.corpus is not None:
        sets["corpus_test"] = split_clips(args.corpus, "test", args.limit)
    if args.general is not None:
        sets["general_test"] = split_clips(args.general, "test", args.limit)
    results = {"vae": desc, "decoded": "posterior samples (seed 0)" if args.sample else "posterior mean",
               "notes": notes, "deepmimic_rig": args.deepmimic_rig, "sets": {}}
    for set_name, clips in sets.items():
        pairs: list = []
        rows = {name: measure_clip(vae, mean, std, f, pairs, sample=args.sample) for name, f in clips.items()}
        summary = summarise(rows)
        channels = root_channel_stats(pairs, int(vae.config.downsample))
        results["sets"][set_name] = {"summary": summary, "root_channels": channels, "clips": rows}
        print(f"\n== {set_name}: {summary['clips']} clips, root-aligned MPJPE median {summary['mpjpe_median_cm']:.1f} cm, "
              f"max {summary['mpjpe_max_cm']:.1f} cm; global median {summary['global_median_cm']:.1f} cm, "
              f"max {summary['global_max_cm']:.1f} cm; yaw drift median {summary['yaw_drift_median_deg']:.1f} deg, "
              f"max {summary['yaw_drift_max_deg']:.1f} deg; ric error median {summary['ric_median_cm']:.2f} cm")
        rv, rl = channels["rot_vel"], channels["rot_vel_latent"]
        print(f"  root angular velocity: rms {rv['rms_rec']:.4f} (true {rv['rms_true']:.4f}) rad/frame, "
              f"corr {rv['corr']:.2f}; per latent frame corr {rl['corr']:.2f}, R^2 {rl['r2']:.2f}")
        if set_name in ("humanml3d_012314", "deepmimic"):
            print(f"  {'clip':24s} {'frames':>6s} {'MPJPE cm':>9s} {'global cm':>10s} {'yaw drift deg':>14s}")
            for name, r in rows.items():
                print(f"  {name:24s} {r['frames']:6d} {r['mpjpe_cm']:9.1f} {r['global_cm']:10.1f} "
                      f"{r['yaw_drift_deg']:14.1f}")
    real = {**results["sets"]["humanml3d_012314"]["clips"], **results["sets"].get("deepmimic", {}).get("clips", {})}
    results["real_summary"] = summarise(real)
    s = results["real_summary"]
    print(f"\n== real clips together (012314 + DeepMimic, {s['clips']} clips): root-aligned median "
          f"{s['mpjpe_median_cm']:.1f} cm, max {s['mpjpe_max_cm']:.1f} cm; global median {s['global_median_cm']:.1f} cm "
          f"(issue 21 targets: <= 4, <= 8, <= 15)")
    for n in notes:
        print(f"note: {n}")
    if args.json:
        args.json.write_text(json.dumps(results, indent=2) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
