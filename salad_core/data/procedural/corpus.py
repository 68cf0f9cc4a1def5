"""Build the procedural motion-language corpus in the HumanML3D layout, and measure it.

Layout written by :func:`build_corpus` (``<id>`` = 6 digits, ``M<id>`` its mirror)::

    new_joint_vecs/<id>.npy   (N-1, 263) float32   joints_to_features of the generated joints
    new_joints/<id>.npy       (N-1, 22, 3) float32 features_to_joints of those features
    texts/<id>.txt            caption#word/POS ...#0.0#0.0 per line (3 or 4 captions)
    annotations/<id>.json     per caption: phrase word span, driven body parts, frame interval
    train.txt val.txt test.txt all.txt   splits 0.80 / 0.05 / 0.15 (mirrors beside originals)
    Mean.npy Std.npy          from the training split (HumanML3D's block-averaged std)
    corpus.json               generator version, seed, size and counts

Every motion is generated from its own random stream ``(seed, index)``, so the files do not
depend on the number of workers and two builds with the same seed are byte-identical.

With ``general=N`` (``salad corpus build --with-general [N]``) the build also writes the first ``N``
motions of the general-motion set (:func:`~.general.generate_general` with the same seed: the clips
the general VAE set of that seed holds) with captions (:mod:`.general_language`), as ``G<id>`` and
their mirrors ``MG<id>``, into the same folders and splits (each general motion keeps the split the
general set gives it). Clips with nothing nameable whole are left out. Such a build is corpus
:data:`GENERAL_CORPUS_VERSION` (2.8); a build without them stays :data:`GENERATOR_VERSION` (2.7),
byte for byte.
"""
from __future__ import annotations

import hashlib
import io
import json
import logging
import os
import shutil
from collections import Counter
from collections.abc import Callable
from pathlib import Path

import numpy as np

from ...motion import compute_mean_std, features_to_joints, joints_to_features, mirror_joints
from ...skeleton import PART_MIRROR, PART_NAMES, get_skeleton
from ..texts import format_text_line, parse_text_line, split_words
from .checks import bone_length_error, foot_sliding, joint_angles, part_speeds, phrase_activity
from .composition import Clip, generate_clip
from .kinematics import FPS, body_model
from .language import Caption, mirror_caption, parse_prompt, render_captions
from .primitives import PRIMITIVES, Action, primitive_parts
from .parallel import run_jobs

__all__ = ["build_corpus", "corpus_figures", "corpus_digest", "make_motion", "make_general_captioned", "SIZES",
           "GENERATOR_VERSION", "GENERAL_CORPUS_VERSION", "SPLITS", "npy_bytes", "write_motion", "split_indices",
           "split_ids", "general_split_ids"]

logger = logging.getLogger(__name__)

#: Bump when the generator's output changes. 2.7: whole-body actions with their own
#: captions (touch_toes, swing, reach_up, balance; side and back kicks, the side lunge), the draw
#: reweighted (kicks, spins and runs more; sitting, lying down and getting up and stairs more to keep
#: the root height's spread: see :data:`.primitives.PRIMITIVES`), held hands re-solved nearest to
#: the arm's own controls (:func:`.reach.nearest_controls`).
GENERATOR_VERSION = "2.7"
#: The version of a build with the captioned general-motion set (``build_corpus(general=N)``, N > 0):
#: 2.7's action clips unchanged plus general clips with captions.
GENERAL_CORPUS_VERSION = "2.8"
#: Motions (before mirroring) of each named size.
SIZES = {"tiny": 200, "small": 1000, "default": 4000}
#: Split fractions (HumanML3D's proportions).
SPLITS = (("train", 0.80), ("val", 0.05), ("test", 0.15))
_LAYOUT_DIRS = ("new_joint_vecs", "new_joints", "texts", "annotations")
_LAYOUT_FILES = ("train.txt", "val.txt", "test.txt", "all.txt", "Mean.npy", "Std.npy", "corpus.json")


# ----------------------------------------------------------------------------- one motion
def npy_bytes(arr: np.ndarray) -> bytes:
    """The bytes of ``arr`` as a ``.npy`` file (no pickle), as the build writes them."""
    buf = io.BytesIO()
    np.save(buf, arr, allow_pickle=False)
    return buf.getvalue()


def _annotation(name: str, rows: int, clip: Clip, captions: list[Caption], mirrored: bool) -> dict:
    caps = []
    for cap in captions:
        words = split_words(cap.text)
        phrases = []
        for ev, (i0, i1) in zip(clip.events, cap.spans):
            parts = ev.parts
            if mirrored:
                parts = tuple(PART_NAMES[PART_MIRROR[PART_NAMES.index(p)]] for p in parts)
            parts = [p for p in PART_NAMES if p in parts]          # canonical order
            f0, f1 = min(ev.frames[0], rows), min(ev.frames[1], rows)
            phrases.append({"text": " ".join(words[i0:i1]), "words": [i0, i1], "parts": parts,
                            "frames": [f0, f1]})
        caps.append({"caption": cap.text, "phrases": phrases})
    return {"name": name, "num_frames": rows, "fps": int(FPS), "captions": caps}


def _texts(captions: list[Caption]) -> str:
    lines = [format_text_line(c.text, list(c.tokens), 0.0, 0.0) for c in captions]
    return "\n".join(lines) + "\n"


def _clip_files(name: str, joints: np.ndarray, captions: list[Caption], mirror: Callable[[Caption], Caption],
               annotation: Callable[[str, int, list[Caption], bool], dict]) -> dict:
    """The files of clip ``name`` (joints ``(frames, J, 3)``) and of its mirror ``M<name>``: features,
    recovered joints, texts and ``annotation(key, rows, captions, mirrored)``; the mirror's captions are
    ``mirror(caption)`` of each."""
    out = {}
    for mirrored in (False, True):
        clip_joints = mirror_joints(joints) if mirrored else joints
        feats = joints_to_features(clip_joints)
        rec = features_to_joints(feats).astype(np.float32)
        caps = [mirror(c) for c in captions] if mirrored else captions
        key = ("M" + name) if mirrored else name
        ann = annotation(key, feats.shape[0], caps, mirrored)
        out[key] = {"new_joint_vecs": npy_bytes(feats), "new_joints": npy_bytes(rec), "texts": _texts(caps),
                    "annotations": json.dumps(ann, separators=(",", ":")) + "\n"}
    return out


def make_motion(seed: int, index: int) -> dict:
    """Generate motion ``index`` of a corpus with ``seed`` and its mirror.

    Returns ``{name: {"new_joint_vecs": bytes, "new_joints": bytes, "texts": str,
    "annotations": str}}`` for ``<id>`` and ``M<id>``, plus ``"_meta"`` (frames, kinds).
    """
    rng = np.random.default_rng([int(seed), int(index)])
    body = body_model("humanml3d")
    clip = generate_clip(rng, body)
    n_caps = 4 if rng.random() < 0.3 else 3
    captions = render_captions(clip.plan, rng, n_caps)
    out = _clip_files(f"{index:06d}", clip.joints, captions, mirror_caption,
                      lambda key, rows, caps, mirrored: _annotation(key, rows, clip, caps, mirrored))
    out["_meta"] = {"frames": int(clip.num_frames - 1), "captions": len(captions),
                    "kinds": [e.action.kind for e in clip.events]}
    return out


def _general_annotation(name: str, rows: int, mode: str, steps: list, captions: list[Caption], mirrored: bool) -> dict:
    caps = []
    for cap in captions:
        words = split_words(cap.text)
        phrases = []
        for st, (i0, i1) in zip(steps, cap.spans):
            parts = st.parts
            if mirrored:
                parts = tuple(PART_NAMES[PART_MIRROR[PART_NAMES.index(p)]] for p in parts)
            parts = [p for p in PART_NAMES if p in parts]
            f0, f1 = min(st.frames[0], rows), min(st.frames[1], rows)
            phrases.append({"text": " ".join(words[i0:i1]), "words": [i0, i1], "parts": parts, "frames": [f0, f1]})
        caps.append({"caption": cap.text, "phrases": phrases})
    return {"name": name, "num_frames": rows, "fps": int(FPS), "mode": mode, "captions": caps}


def make_general_captioned(seed: int, index: int) -> dict:
    """General motion ``index`` of ``seed`` (:func:`~.general.generate_general`) with captions, and its mirror.

    Returns the files of ``G<id>`` and ``MG<id>`` as :func:`make_motion` does, plus ``"_meta"``
    (mode, frames, captions, step actions); only ``"_meta"`` (``captions`` 0) when the clip has
    nothing nameable (:func:`~.general_language.general_steps` is empty).
    """
    from .general import generate_general
    from .general_language import general_steps, mirror_general_caption, render_general_captions

    clip = generate_general(seed, index)
    steps = general_steps(clip)
    meta = {"mode": clip.mode, "frames": int(clip.num_frames - 1), "captions": 0,
            "actions": [st.action for st in steps]}
    if not steps:
        return {"_meta": meta}
    rng = np.random.default_rng([int(seed), int(index), 0xCA7])
    n_caps = 4 if rng.random() < 0.3 else 3
    captions = render_general_captions(steps, rng, n_caps)
    out = _clip_files(f"G{index:06d}", clip.joints, captions, mirror_general_caption,
                      lambda key, rows, caps, mirrored: _general_annotation(key, rows, clip.mode, steps, caps, mirrored))
    meta["captions"] = len(captions)
    out["_meta"] = meta
    return out


def write_motion(root: Path, motion: dict) -> None:
    """Write one :func:`make_motion` result (the clip and its mirror) into the corpus layout under ``root``."""
    for key, files in motion.items():
        if key.startswith("_"):
            continue
        (root / "new_joint_vecs" / f"{key}.npy").write_bytes(files["new_joint_vecs"])
        (root / "new_joints" / f"{key}.npy").write_bytes(files["new_joints"])
        (root / "texts" / f"{key}.txt").write_text(files["texts"], encoding="utf-8")
        (root / "annotations" / f"{key}.json").write_text(files["annotations"], encoding="utf-8")


def _job(args: tuple[int, int, str]) -> dict:
    seed, index, root = args
    motion = make_motion(seed, index)
    write_motion(Path(root), motion)
    return motion["_meta"]


def _general_job(args: tuple[int, int, str]) -> dict:
    seed, index, root = args
    motion = make_general_captioned(seed, index)
    write_motion(Path(root), motion)
    return motion["_meta"]


# ----------------------------------------------------------------------------- the corpus
def _resolve_size(size: str | int) -> int:
    if isinstance(size, bool):
        raise ValueError(f"size={size!r}; allowed: {', '.join(SIZES)} or a positive int")
    if isinstance(size, int):
        if size < 20:
            raise ValueError(f"size={size} motions is too small for the splits; use at least 20")
        return size
    if size not in SIZES:
        raise ValueError(f"size={size!r}; allowed: {', '.join(SIZES)} or a positive int")
    return SIZES[size]


def _prepare(out: Path, overwrite: bool) -> None:
    if out.exists() and not out.is_dir():
        raise NotADirectoryError(f"out_dir {out} exists and is not a folder")
    if out.is_dir() and any(out.iterdir()):
        if not overwrite:
            raise FileExistsError(f"out_dir {out} is not empty; pass overwrite=True (salad corpus build "
                                  f"--force) to replace a corpus there")
        for d in _LAYOUT_DIRS:
            shutil.rmtree(out / d, ignore_errors=True)
        for f in _LAYOUT_FILES:
            (out / f).unlink(missing_ok=True)
    for d in _LAYOUT_DIRS:
        (out / d).mkdir(parents=True, exist_ok=True)


def split_indices(n: int, seed: int, salt: int = 7919) -> dict[str, list[int]]:
    """Motion indices ``0..n-1`` of each split (:data:`SPLITS` fractions), sorted; a seeded permutation.

    ``salt`` separates independent builds drawn with the same seed (the corpus uses 7919, the general
    motions 104729).
    """
    order = np.random.default_rng([int(seed), int(salt)]).permutation(n)
    bounds, start, out = np.cumsum([f for _, f in SPLITS]), 0, {}
    for (name, _), b in zip(SPLITS, bounds):
        stop = n if name == SPLITS[-1][0] else int(round(b * n))
        out[name] = sorted(int(i) for i in order[start:stop])
        start = stop
    return out


def split_ids(n: int, seed: int) -> dict[str, list[str]]:
    """The corpus's clip ids of each split: every motion ``000123`` with its mirror ``M000123``."""
    return {name: sorted([f"{i:06d}" for i in ids] + [f"M{i:06d}" for i in ids])
            for name, ids in split_indices(n, seed).items()}


def general_split_ids(n: int, seed: int, keep=None) -> dict[str, list[str]]:
    """Ids of the captioned general clips of each split: ``G000123`` with its mirror ``MG000123``, the
    split the general-motion set of ``seed`` gives motion 123 (salt 104729); ``keep``: the indices
    with captions (default all)."""
    keep = None if keep is None else set(keep)
    return {name: sorted([f"G{i:06d}" for i in ids if keep is None or i in keep]
                         + [f"MG{i:06d}" for i in ids if keep is None or i in keep])
            for name, ids in split_indices(n, seed, salt=104729).items()}


def _resolve_general(general, n: int) -> int:
    if general is None or general is False:
        return 0
    if general is True or general == "auto":
        return n // 2
    if isinstance(general, (int, np.integer)) and not isinstance(general, bool) and general >= 0:
        if 0 < general < 20:
            raise ValueError(f"general={general} motions is too small for the splits; use 0 or at least 20")
        return int(general)
    raise ValueError(f"general={general!r}; allowed: 0 (none), 'auto' (half the corpus's motions) or an int >= 20")


def build_corpus(out_dir: str | os.PathLike, size: str | int = "default", seed: int = 0,
                 overwrite: bool = False, progress: bool = True, workers: int | None = None,
                 general: int | str = 0) -> dict:
    """Generate the procedural corpus into ``out_dir`` (HumanML3D layout, see module doc).

    Parameters
    ----------
    out_dir : path
        Folder to write; must be empty or absent unless ``overwrite``.
    size : "tiny" (200 motions), "small" (1,000), "default" (4,000) or an int
        Motions before mirroring; the corpus holds twice as many clips.
    seed : int
        Same seed, same files (byte for byte).
    overwrite : bool
        Replace the corpus files in a non-empty ``out_dir`` (other files are left alone).
    progress : bool
        Show a tqdm progress bar.
    workers : int, optional
        Processes to generate with (default: 1 for up to 400 motions, else up to 2 CPUs).
    general : int or "auto"
        Also write the first ``general`` motions of the general-motion set with captions (``G<id>``,
        ``MG<id>``; see the module doc); "auto": half as many as ``size``. 0 (default): the action
        corpus alone, version :data:`GENERATOR_VERSION`; otherwise version :data:`GENERAL_CORPUS_VERSION`.

    Returns
    -------
    dict: the summary also written to ``corpus.json``.
    """
    n = _resolve_size(size)
    n_general = _resolve_general(general, n)
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise ValueError(f"seed={seed!r} must be a non-negative int")
    out = Path(out_dir)
    _prepare(out, overwrite)
    if workers is None:
        workers = 1 if n <= 400 else max(1, min(2, os.cpu_count() or 1))
    jobs = [(int(seed), i, str(out)) for i in range(n)]
    metas: list[dict] = run_jobs(_job, jobs, workers, desc="procedural corpus", chunksize=8, progress=progress)
    splits = split_ids(n, int(seed))
    general_metas: list[dict] = []
    if n_general:
        jobs = [(int(seed), i, str(out)) for i in range(n_general)]
        general_metas = run_jobs(_general_job, jobs, workers, desc="captioned general motion", chunksize=8,
                                 progress=progress)
        kept_idx = [i for i, m in enumerate(general_metas) if m["captions"]]
        for name, ids in general_split_ids(n_general, int(seed), kept_idx).items():
            splits[name] = splits[name] + ids
    for name, ids in splits.items():
        (out / f"{name}.txt").write_text("\n".join(ids) + "\n", encoding="utf-8")
    all_ids = sorted(i for ids in splits.values() for i in ids)
    (out / "all.txt").write_text("\n".join(all_ids) + "\n", encoding="utf-8")
    sk = get_skeleton("humanml3d")
    mean, std = compute_mean_std((np.load(out / "new_joint_vecs" / f"{i}.npy") for i in splits["train"]), sk)
    np.save(out / "Mean.npy", mean)
    np.save(out / "Std.npy", std)

    frames = np.array([m["frames"] for m in metas])
    kinds = Counter(k for m in metas for k in m["kinds"])
    summary = {
        "generator": "salad_core.data.procedural",
        "version": GENERAL_CORPUS_VERSION if n_general else GENERATOR_VERSION,
        "seed": int(seed),
        "size": size if isinstance(size, str) else int(size),
        "skeleton": "humanml3d",
        "fps": int(FPS),
        "motions": n,
        "clips": 2 * n,
        "splits": {k: len(v) for k, v in splits.items()},
        "captions": int(2 * sum(m["captions"] for m in metas)),
        "frames": {"total": int(2 * frames.sum()), "mean": round(float(frames.mean()), 2),
                   "min": int(frames.min()), "max": int(frames.max())},
        "primitives": {k: kinds.get(k, 0) for k in PRIMITIVES},
    }
    if n_general:
        from .general_build import GENERAL_VERSION

        kept = [m for m in general_metas if m["captions"]]
        g_frames = np.array([m["frames"] for m in kept]) if kept else np.zeros(1)
        summary["general"] = {
            "generator": "salad_core.data.procedural.general", "version": GENERAL_VERSION,
            "motions": n_general, "captioned": len(kept), "clips": 2 * len(kept),
            "captions": int(2 * sum(m["captions"] for m in kept)),
            "frames": {"total": int(2 * g_frames.sum()), "mean": round(float(g_frames.mean()), 2)},
            "modes": dict(sorted(Counter(m["mode"] for m in kept).items())),
            "uncaptioned_modes": dict(sorted(Counter(m["mode"] for m in general_metas if not m["captions"]).items())),
            "actions": dict(sorted(Counter(a for m in kept for a in m["actions"]).items())),
        }
        summary["clips"] += 2 * len(kept)
        summary["captions"] += summary["general"]["captions"]
    (out / "corpus.json").write_text(json.dumps(summary, indent=2) + "\n", encoding="utf-8")
    logger.info("procedural corpus: %d clips (%d motions + mirrors) in %s", 2 * n, n, out)
    return summary


# ----------------------------------------------------------------------------- figures
def _phrase_secondary(text: str) -> tuple[str, ...]:
    """Parts the phrase's action moves incidentally (via the parser and the registry)."""
    parsed = parse_prompt(text)
    if not parsed or len(parsed) != 1:
        return ()
    p = parsed[0]
    spec = PRIMITIVES[p.kind]
    side = p.side if p.side in spec.sides else spec.sides[0]
    reps = p.reps if p.reps in spec.reps else spec.reps[0]
    action = Action(p.kind, side, p.mods, reps, p.variant)
    return primitive_parts(action)[1]


def _read_ids(root: Path, split: str) -> list[str]:
    return [ln.strip() for ln in (root / f"{split}.txt").read_text().splitlines() if ln.strip()]


def corpus_figures(root: str | os.PathLike, reference: str | os.PathLike | None = None,
                   max_clips: int | None = None) -> dict:
    """Measure a corpus folder: plausibility of the motions and correctness of the annotations.

    Parameters
    ----------
    root : path of a corpus built by :func:`build_corpus`
    reference : path, optional
        A HumanML3D-layout folder (e.g. the real sample 012314) whose foot sliding is measured
        with the same function for comparison.
    max_clips : int, optional
        Measure only the first clips of ``all.txt``.

    Returns
    -------
    dict of figures (see the keys; all lengths in metres, speeds in m/s).
    """
    root = Path(root)
    sk = get_skeleton("humanml3d")
    ids = _read_ids(root, "all")[:max_clips]
    bone_std, bone_err, min_h = 0.0, 0.0, np.inf
    slide_sum, slide_n, slide_p95 = 0.0, 0, []
    knee_max, elbow_max, knee_back, ankle_rng = 0.0, 0.0, np.inf, [np.inf, -np.inf]
    ratios_idle, ratios_others, driven_min = [], [], np.inf
    n_caps, n_parsed, caps_per = 0, 0, []
    mirror_ok, mirror_n = 0, 0
    secondary_cache: dict[str, tuple[str, ...]] = {}
    for mid in ids:
        joints = np.load(root / "new_joints" / f"{mid}.npy").astype(np.float64)
        b = bone_length_error(joints, sk)
        bone_std, bone_err = max(bone_std, b["max_std"]), max(bone_err, b["max_error"])
        min_h = min(min_h, float(joints[..., 1].min()))
        fs = foot_sliding(joints, sk)
        slide_sum, slide_n = slide_sum + fs["sum"], slide_n + fs["count"]
        ang = joint_angles(joints, sk)
        knee_max = max(knee_max, float(ang["knee"].max()))
        elbow_max = max(elbow_max, float(ang["elbow"].max()))
        knee_back = min(knee_back, float(ang["knee_bend"].min()))
        ankle_rng = [min(ankle_rng[0], float(ang["ankle"].min())), max(ankle_rng[1], float(ang["ankle"].max()))]
        ann = json.loads((root / "annotations" / f"{mid}.json").read_text())
        lines = [parse_text_line(ln, f"{mid}.txt") for ln in (root / "texts" / f"{mid}.txt").read_text().splitlines() if ln]
        caps_per.append(len(lines))
        speeds = part_speeds(joints, sk)
        for cap in ann["captions"]:
            n_caps += 1
            if mid.lstrip("M").startswith("G"):                # a captioned general clip (corpus 2.8)
                from .general_language import parse_general_prompt

                n_parsed += parse_general_prompt(cap["caption"]) is not None
            else:
                n_parsed += parse_prompt(cap["caption"]) is not None
            sec = []
            for ph in cap["phrases"]:
                if ph["text"] not in secondary_cache:
                    secondary_cache[ph["text"]] = _phrase_secondary(ph["text"])
                sec.append(secondary_cache[ph["text"]])
            for r in phrase_activity(speeds, cap["phrases"], sec):
                ratios_idle.append(r["ratio_idle"])
                ratios_others.append(r["ratio_others"])
                driven_min = min(driven_min, r["driven"])
        if mid.startswith("M"):
            orig = json.loads((root / "annotations" / f"{mid[1:]}.json").read_text())
            for c_m, c_o in zip(ann["captions"], orig["captions"]):
                for p_m, p_o in zip(c_m["phrases"], c_o["phrases"]):
                    mirror_n += 1
                    want = sorted(PART_NAMES[PART_MIRROR[PART_NAMES.index(p)]] for p in p_o["parts"])
                    mirror_ok += sorted(p_m["parts"]) == want and p_m["words"] == p_o["words"]
    ri = np.asarray(ratios_idle)
    ro = np.asarray(ratios_others)
    finite_i, finite_o = ri[np.isfinite(ri)], ro[np.isfinite(ro)]
    figures = {
        "clips": len(ids),
        "captions": n_caps,
        "captions_per_clip_min": int(min(caps_per)) if caps_per else 0,
        "captions_in_language": n_parsed / max(n_caps, 1),
        "bone_length_std_max": bone_std,
        "bone_length_error_max": bone_err,
        "min_joint_height": float(min_h),
        "foot_sliding": slide_sum / max(slide_n, 1),
        "knee_flexion_max_deg": knee_max,
        "elbow_flexion_max_deg": elbow_max,
        "ankle_angle_range_deg": ankle_rng,
        "knee_bend_min": knee_back,
        "phrases": int(ri.size),
        "phrase_driven_activity_min": float(driven_min),
        "phrase_ratio_idle_min": float(finite_i.min()) if finite_i.size else float("inf"),
        "phrase_ratio_idle_median": float(np.median(finite_i)) if finite_i.size else float("inf"),
        "phrase_ratio_idle_pass": float((ri > 1.0).mean()) if ri.size else 0.0,
        "phrase_ratio_others_median": float(np.median(finite_o)) if finite_o.size else float("inf"),
        "phrase_ratio_others_pass": float((ro > 1.0).mean()) if ro.size else 0.0,
        "mirror_annotations_consistent": mirror_ok / max(mirror_n, 1),
    }
    if reference is not None:
        ref = Path(reference)
        s, c = 0.0, 0
        for f in sorted((ref / "new_joints").glob("*.npy")):
            fs = foot_sliding(np.load(f).astype(np.float64), sk)
            s, c = s + fs["sum"], c + fs["count"]
        figures["foot_sliding_reference"] = s / max(c, 1)
    return figures


def corpus_digest(root: str | os.PathLike) -> str:
    """SHA-256 over every file of a corpus (relative paths and bytes), for determinism checks."""
    root = Path(root)
    h = hashlib.sha256()
    for path in sorted(p for p in root.rglob("*") if p.is_file()):
        h.update(str(path.relative_to(root)).encode())
        h.update(path.read_bytes())
    return h.hexdigest()
