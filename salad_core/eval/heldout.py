"""Data to evaluate on without the real datasets: held-out clips of the procedural corpus, and the
data folder and evaluator a reproduction notebook's parameters ask for.

- :func:`heldout_corpus`: a small folder of procedural-corpus clips from the split the shipped
  weights never trained on (the test split of ``build_corpus(size="default", seed=0)``), so quick
  evaluations score unseen motions without building the whole corpus;
- :func:`procedural_eval_corpus`: QUICK held-out clips, a given folder, or the whole default corpus;
- :func:`evaluation_data`: the data folder and evaluator of QUICK, procedural FULL, or the official
  release on HumanML3D / KIT-ML.
"""
from __future__ import annotations

import json
import logging
import os
from pathlib import Path
from typing import Any

import numpy as np

__all__ = ["heldout_corpus", "procedural_eval_corpus", "evaluation_data"]

logger = logging.getLogger(__name__)


def heldout_corpus(out_dir: str | os.PathLike, motions: int = 40, *, split: str = "test",
                   size: str | int = "default", seed: int = 0) -> Path:
    """Write the first ``motions`` motions (and their mirrors) of one split of a procedural corpus.

    The clips are byte-identical to those ``build_corpus(..., size=size, seed=seed)`` writes for
    that split, without generating the rest of the corpus (about 25 ms per motion). They are built
    by the installed corpus generator (``GENERATOR_VERSION``), so no shipped model saw them in
    training; they are drawn from the shipped models' own corpus only while the generator is at the
    version those models were trained on (their model cards name it: SALAD 0.3 and the evaluator
    2.4, KeyMotion 0.1 and the ablations 1.0; the generator is at 2.7), otherwise they include
    actions and words the models never learnt and every row, real included, scores lower.

    Parameters
    ----------
    out_dir : path
        Created; must be absent or empty.
    motions : int
        Motions taken (in id order) from the split; the folder holds ``2 * motions`` clips.
    split : {"train", "val", "test"}
    size, seed
        The corpus (as :func:`salad_core.data.procedural.build_corpus`).

    Returns
    -------
    Path
        ``out_dir`` in the HumanML3D layout (``new_joint_vecs``, ``new_joints``, ``texts``,
        ``annotations``, ``<split>.txt``, ``heldout.json``). It has no ``Mean.npy``/``Std.npy``:
        the evaluator and the pipelines normalise with their own statistics.
    """
    # the corpus's own split rule and writer, so the ids and bytes cannot drift from build_corpus
    from salad_core.data.procedural.corpus import SIZES, make_motion, split_ids, write_motion

    if isinstance(size, str):
        if size not in SIZES:
            raise ValueError(f"size={size!r}; allowed: {', '.join(SIZES)} or an int")
        n_total = SIZES[size]
    elif isinstance(size, (int, np.integer)) and not isinstance(size, bool) and size >= 20:
        n_total = int(size)
    else:
        raise ValueError(f"size={size!r}; allowed: {', '.join(SIZES)} or an int >= 20")
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise ValueError(f"seed={seed!r} must be a non-negative int")
    splits = split_ids(n_total, int(seed))
    if split not in splits:
        raise ValueError(f"split={split!r}; allowed: {sorted(splits)}")
    ids = sorted({int(name.lstrip("M")) for name in splits[split]})
    if isinstance(motions, bool) or not isinstance(motions, (int, np.integer)) or not 1 <= motions <= len(ids):
        raise ValueError(f"motions={motions!r} must be an int from 1 to {len(ids)} (the {split} split's motions)")
    out = Path(out_dir)
    if out.exists() and (not out.is_dir() or any(out.iterdir())):
        raise FileExistsError(f"out_dir {out} exists and is not an empty folder")
    for d in ("new_joint_vecs", "new_joints", "texts", "annotations"):
        (out / d).mkdir(parents=True, exist_ok=True)
    names = []
    for i in ids[:motions]:
        motion = make_motion(int(seed), i)
        write_motion(out, motion)
        names += [k for k in motion if not k.startswith("_")]
    names.sort()
    (out / f"{split}.txt").write_text("\n".join(names) + "\n", encoding="utf-8")
    doc = {"generator": "salad_core.data.procedural", "corpus_size": size if isinstance(size, str) else n_total,
           "seed": int(seed), "split": split, "motions": int(motions), "clips": len(names)}
    (out / "heldout.json").write_text(json.dumps(doc, indent=2) + "\n", encoding="utf-8")
    logger.info("held-out corpus: %d %s clips of the %s corpus (seed %d) in %s", len(names), split, size, seed, out)
    return out


def procedural_eval_corpus(quick: bool, out_dir: str | os.PathLike, *, data_root: str | os.PathLike | None = None,
                           heldout_motions: int = 32) -> Path:
    """The procedural data the Table-1 / CFG-sweep notebooks score the shipped models on.

    QUICK: ``heldout_motions`` held-out test motions (and mirrors) in a fresh temporary folder
    (:func:`heldout_corpus`); else ``data_root`` if given; else the whole default corpus,
    built once into ``out_dir/procedural_corpus`` (the FULL protocol on the procedural corpus).
    """
    out_dir = Path(out_dir)
    if quick:
        import tempfile

        return heldout_corpus(Path(tempfile.mkdtemp()) / "heldout", heldout_motions)
    if data_root:
        return Path(data_root)
    from salad_core.data.procedural import build_corpus

    data = out_dir / "procedural_corpus"
    if not (data / "test.txt").is_file():
        build_corpus(data, size="default", seed=0)
    return data


def evaluation_data(quick: bool, out_dir: str | os.PathLike, *, data_root: str | os.PathLike | None = None,
                    checkpoints: str | os.PathLike | None = None, dataset: str = "humanml3d",
                    heldout_motions: int = 32) -> tuple[Path, Any]:
    """The data folder and the evaluator of a reproduction notebook, from its parameters cell.

    FULL mode with ``checkpoints`` (the official release): ``data_root`` (HumanML3D or KIT-ML,
    required) and the official T2M evaluator of ``dataset``. Otherwise the procedural data of
    :func:`procedural_eval_corpus` and the shipped procedural-corpus evaluator.

    Returns
    -------
    (Path, T2MEvaluator)
        The evaluator's ``source`` names where it came from (recorded in every result).
    """
    if not quick and checkpoints:
        from salad_core.eval.t2m import T2MEvaluator

        if not data_root:
            raise ValueError("FULL mode with CHECKPOINTS needs DATA_ROOT: the HumanML3D / KIT-ML folder")
        evaluator = T2MEvaluator.from_official(checkpoints, dataset)
        evaluator.source = f"official T2M evaluator ({dataset})"
        return Path(data_root), evaluator
    from salad_core.eval.train_evaluator import load_packaged_evaluator

    data = procedural_eval_corpus(quick, out_dir, data_root=data_root, heldout_motions=heldout_motions)
    return data, load_packaged_evaluator()[0]
