"""Building blocks of the reproduction notebooks: published numbers, held-out data, official weights,
KeyMotion round trips.

- :func:`paper_table1`: SALAD (CVPR 2025) Table 1 as printed, in the shape of
  :func:`~salad_core.eval.protocol.results_frame`, for ``to_markdown(ours, reference=paper_table1())``.
  Published numbers only; nothing here is computed. :func:`paper_denoiser_ablations` likewise for
  Table 3 and supplement Tables 2-3.
- :func:`heldout_corpus`: a small folder of procedural-corpus clips from the split the shipped
  weights never trained on (the test split of ``build_corpus(size="default", seed=0)``), so quick
  evaluations score unseen motions without building the whole corpus.
- :func:`evaluation_data`: the data folder and evaluator a notebook's parameters ask for (QUICK,
  procedural FULL, or the official release on HumanML3D / KIT-ML).
- :func:`read_official_options` and :func:`official_salad_pipeline`: a :class:`SaladPipeline` from
  the official release's ``checkpoints`` folder (FULL mode of the notebooks).
- :class:`LengthBucketed`: a SALAD generator that splits each batch into groups of similar length,
  so short motions are not denoised at the batch's longest length; the motions are the same.
- :func:`keyframe_roundtrip` and :func:`infill_from_keyframes`: KeyMotion's keyframe VAE and MMAE
  on a given motion's own keyframes, with errors in metres.
"""
from __future__ import annotations

import ast
import json
import logging
import os
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any, Sequence

import numpy as np
import pandas as pd
import torch

from .protocol import METRICS, paper_frame, paper_row

if TYPE_CHECKING:
    from salad_core.keymotion.pipeline import KeyMotionPipeline
    from salad_core.pipeline import SaladPipeline

__all__ = [
    "PAPER_TABLE1",
    "PAPER_TABLE1_DEFAULT_ROWS",
    "paper_table1",
    "PAPER_DENOISER_ABLATIONS",
    "paper_denoiser_ablations",
    "heldout_corpus",
    "procedural_eval_corpus",
    "evaluation_data",
    "read_official_options",
    "official_salad_pipeline",
    "LengthBucketed",
    "BucketedOutput",
    "length_groups",
    "KeyframeRoundTrip",
    "Infilling",
    "keyframe_roundtrip",
    "infill_from_keyframes",
]

logger = logging.getLogger(__name__)

_NA = None   # a cell the paper prints as "-"

# SALAD (CVPR 2025) Table 1, test sets: method -> (top-1, top-2, top-3, FID, MM-Dist, Diversity,
# MultiModality) as (mean, 95% half-width), in METRICS order. Copied from the paper; never computed.
PAPER_TABLE1: dict[str, dict[str, tuple]] = {
    "humanml3d": {
        "Real motion": ((.511, .003), (.703, .003), (.797, .002), (.002, .000), (2.974, .008), (9.503, .065), _NA),
        "T2M": ((.457, .002), (.639, .003), (.740, .003), (1.067, .002), (3.340, .008), (9.188, .002), (2.090, .083)),
        "AttT2M": ((.499, .003), (.690, .002), (.786, .002), (.112, .006), (3.038, .007), (9.700, .090), (2.452, .051)),
        "ParCo": ((.515, .003), (.706, .003), (.801, .002), (.109, .005), (2.927, .008), (9.576, .088), (1.382, .060)),
        "MoMask": ((.521, .002), (.713, .002), (.807, .002), (.045, .002), (2.958, .008), _NA, (1.241, .040)),
        "MDM": ((.320, .005), (.498, .004), (.611, .007), (.544, .044), (5.566, .027), (9.559, .086), (2.799, .072)),
        "MLD": ((.481, .003), (.673, .003), (.772, .002), (.473, .013), (3.196, .010), (9.724, .082), (2.413, .079)),
        "MotionDiffuse": ((.491, .001), (.681, .001), (.782, .001), (.630, .001), (3.113, .001), (9.410, .049),
                          (1.553, .042)),
        "ReMoDiffuse": ((.510, .005), (.698, .006), (.795, .004), (.103, .004), (2.974, .016), (9.018, .075),
                        (1.795, .043)),
        "SALAD": ((.581, .003), (.769, .003), (.857, .002), (.076, .002), (2.649, .009), (9.696, .096), (1.751, .062)),
    },
    "kit": {
        "Real motion": ((.424, .005), (.649, .006), (.779, .006), (.031, .004), (2.788, .012), (11.08, .097), _NA),
        "T2M": ((.370, .005), (.569, .007), (.693, .007), (2.770, .109), (3.401, .008), (10.91, .119), (1.482, .065)),
        "AttT2M": ((.413, .006), (.632, .006), (.751, .006), (.870, .039), (3.039, .021), (10.96, .123), (2.281, .047)),
        "ParCo": ((.430, .004), (.649, .007), (.772, .006), (.453, .027), (2.820, .028), (10.95, .094), (1.245, .022)),
        "MoMask": ((.433, .007), (.656, .005), (.781, .005), (.204, .011), (2.779, .022), _NA, (1.131, .043)),
        "MDM": ((.164, .004), (.291, .004), (.396, .004), (.497, .021), (9.191, .022), (10.847, .109), (1.907, .214)),
        "MLD": ((.390, .008), (.609, .008), (.734, .007), (.404, .027), (3.204, .027), (10.80, .117), (2.192, .071)),
        "MotionDiffuse": ((.417, .004), (.621, .004), (.739, .004), (1.954, .062), (2.958, .005), (11.10, .143),
                          (.730, .013)),
        "ReMoDiffuse": ((.427, .014), (.641, .004), (.765, .055), (.155, .006), (2.814, .012), (10.80, .105),
                        (1.239, .028)),
        "SALAD": ((.477, .006), (.711, .005), (.828, .005), (.296, .012), (2.585, .016), (11.097, .095), (1.004, .040)),
    },
}
#: Rows :func:`paper_table1` shows by default (the rows this project reproduces).
PAPER_TABLE1_DEFAULT_ROWS = ("Real motion", "SALAD")


def paper_table1(dataset: str = "humanml3d", methods: Sequence[str] | None = PAPER_TABLE1_DEFAULT_ROWS) -> pd.DataFrame:
    """SALAD Table 1 (published numbers) as a :func:`~salad_core.eval.protocol.results_frame`-shaped frame.

    Parameters
    ----------
    dataset : {"humanml3d", "kit"}
    methods : sequence of str or None
        Rows in this order (default: Real motion and SALAD); None: every row of the table.

    Returns
    -------
    DataFrame
        Rows named ``"paper: <method>"`` with ``kind == "paper"``; cells the paper prints as "-"
        are NaN. Pass it as ``reference=`` to :func:`~salad_core.eval.protocol.to_markdown`.
    """
    from salad_core.skeleton import get_skeleton

    key = get_skeleton(dataset).name
    if key not in PAPER_TABLE1:
        raise ValueError(f"dataset={dataset!r}: the paper's Table 1 covers {sorted(PAPER_TABLE1)}")
    table = PAPER_TABLE1[key]
    names = list(table) if methods is None else list(methods)
    unknown = [m for m in names if m not in table]
    if unknown or not names:
        raise ValueError(f"methods={unknown or names!r} are not rows of the paper's Table 1; rows: {list(table)}")
    source = f"SALAD paper (CVPR 2025), Table 1 ({key})"
    return paper_frame([paper_row(method, dict(zip(METRICS, table[method])), source) for method in names])


# SALAD (CVPR 2025) denoiser ablations, HumanML3D test set (supp. Table 3 also KIT-ML): method ->
# (R-precision top-3, FID) as (mean, 95% half-width). Copied from the paper; never computed.
PAPER_DENOISER_ABLATIONS: dict[str, dict[str, dict[str, tuple]]] = {
    "table3": {"humanml3d": {
        "Full model": ((.857, .002), (.076, .002)),
        "w/o ST-Latent": ((.816, .002), (.433, .006)),
        "w/o CrossAttn": ((.778, .002), (.274, .007)),
        "w/o both": ((.752, .002), (.345, .007)),
    }},
    "supp_table2": {"humanml3d": {
        "x-prediction": ((.860, .002), (.111, .003)),
        "epsilon-prediction": ((.803, .002), (.257, .008)),
        "v-prediction": ((.857, .002), (.076, .002)),
    }},
    "supp_table3": {
        "humanml3d": {"with FiLM": ((.857, .002), (.076, .002)), "without FiLM": ((.843, .002), (.087, .003))},
        "kit": {"with FiLM": ((.828, .005), (.296, .012)), "without FiLM": ((.803, .006), (.311, .013))},
    },
}
_TABLE_TITLES = {"table3": "Table 3", "supp_table2": "supplement Table 2", "supp_table3": "supplement Table 3"}


def paper_denoiser_ablations(which: str = "table3", dataset: str = "humanml3d") -> pd.DataFrame:
    """The paper's denoiser ablations (R-precision top-3 and FID only) as a results-frame-shaped
    DataFrame with rows ``"paper: <method>"``, for ``to_markdown(ours, reference=...)``.

    ``which``: ``"table3"`` (w/o ST-Latent, w/o CrossAttn, both), ``"supp_table2"`` (the three
    diffusion parametrisations) or ``"supp_table3"`` (FiLM; HumanML3D and KIT-ML).
    """
    from salad_core.skeleton import get_skeleton

    if which not in PAPER_DENOISER_ABLATIONS:
        raise ValueError(f"which={which!r}; choose one of {sorted(PAPER_DENOISER_ABLATIONS)}")
    key = get_skeleton(dataset).name
    tables = PAPER_DENOISER_ABLATIONS[which]
    if key not in tables:
        raise ValueError(f"the paper's {_TABLE_TITLES[which]} has no {key!r} rows; it covers {sorted(tables)}")
    source = f"SALAD paper (CVPR 2025), {_TABLE_TITLES[which]} ({key})"
    return paper_frame([paper_row(method, {"R-precision top-3": top3, "FID": fid}, source)
                        for method, (top3, fid) in tables[key].items()])


# ----------------------------------------------------------------------------------- data
def heldout_corpus(out_dir: str | os.PathLike, motions: int = 40, *, split: str = "test",
                   size: str | int = "default", seed: int = 0) -> Path:
    """Write the first ``motions`` motions (and their mirrors) of one split of a procedural corpus.

    The clips are byte-identical to those ``build_corpus(..., size=size, seed=seed)`` writes for
    that split, without generating the rest of the corpus (about 25 ms per motion). With the
    defaults they are test clips of the corpus the shipped SALAD, KeyMotion and evaluator weights
    were trained on, which none of them saw in training.

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
    from salad_core.data.procedural.corpus import SIZES, _split_ids, _write_motion, make_motion

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
    splits = _split_ids(n_total, int(seed))
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
        _write_motion(out, motion)
        names += [k for k in motion if not k.startswith("_")]
    names.sort()
    (out / f"{split}.txt").write_text("\n".join(names) + "\n", encoding="utf-8")
    doc = {"generator": "salad_core.data.procedural", "corpus_size": size if isinstance(size, str) else n_total,
           "seed": int(seed), "split": split, "motions": int(motions), "clips": len(names)}
    (out / "heldout.json").write_text(json.dumps(doc, indent=2) + "\n", encoding="utf-8")
    logger.info("held-out corpus: %d %s clips of the %s corpus (seed %d) in %s", len(names), split, size, seed, out)
    return out


# ------------------------------------------------------------------------ official release
_OFFICIAL_DS = {"humanml3d": "t2m", "kit": "kit"}
_CLIP_FOLDERS = {"ViT-B/32": "clip-vit-base-patch32", "ViT-L/14": "clip-vit-large-patch14"}


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


def read_official_options(path: str | os.PathLike) -> dict[str, Any]:
    """Parse an official ``opt.txt`` (``key: value`` lines) into a dict.

    Values become bool, int, float or list where they read as such, else stay strings; the
    ``---- Options ----`` banner lines are skipped.
    """
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"official options file not found: {path}")
    out: dict[str, Any] = {}
    for line in path.read_text(encoding="utf-8").splitlines():
        if ":" not in line or line.lstrip().startswith("-"):
            continue
        key, value = (s.strip() for s in line.split(":", 1))
        if not key:
            continue
        if value in ("True", "False"):
            out[key] = value == "True"
            continue
        try:
            lit = ast.literal_eval(value)     # literals only: numbers, lists, None, quoted strings
        except (ValueError, SyntaxError):
            lit = value
        out[key] = lit
    return out


def official_salad_pipeline(checkpoints_dir: str | os.PathLike, dataset: str = "humanml3d",
                            name: str = "t2m_denoiser_vpred_vaegelu", *, checkpoint: str = "net_best_fid",
                            text_encoder: Any = None, meta_dir: str | os.PathLike | None = None) -> "SaladPipeline":
    """A :class:`~salad_core.pipeline.SaladPipeline` with the official released weights.

    Reads the release's layout (``salad_official_facts`` §6)::

        checkpoints/<t2m|kit>/<name>/opt.txt               denoiser options (vae_name, clip_version, schedule)
        checkpoints/<t2m|kit>/<name>/model/<checkpoint>.tar
        checkpoints/<t2m|kit>/<vae_name>/model/<checkpoint>.tar   (and its opt.txt: activation)
        checkpoints/<t2m|kit>/Comp_v6_KLD005/meta/{mean,std}.npy  normalisation (as the official code)
        checkpoints/clip-vit-base-patch32/                 the CLIP text encoder (HF folder)

    Parameters
    ----------
    checkpoints_dir : path
        The release's ``checkpoints`` folder.
    dataset : {"humanml3d", "kit"}
    name : str
        Denoiser run name (the released HumanML3D one by default).
    checkpoint : str
        Checkpoint stem; inference in the official code always loads ``net_best_fid``.
    text_encoder : encoder or path, optional
        Default: the CLIP folder named by ``clip_version`` in ``opt.txt``.
    meta_dir : path, optional
        Folder with ``mean.npy``/``std.npy`` (default: the evaluator's ``Comp_v6_KLD005/meta``).
    """
    from salad_core.models import Denoiser, MotionVAE, load_official_checkpoint
    from salad_core.pipeline import SaladPipeline
    from salad_core.sampling import DiffusionConfig
    from salad_core.skeleton import get_skeleton
    from salad_core.text import load_text_encoder

    sk = get_skeleton(dataset)
    if sk.name not in _OFFICIAL_DS:
        raise ValueError(f"dataset={dataset!r}: the release has {sorted(_OFFICIAL_DS)}")
    root = Path(checkpoints_dir)
    ds_dir = root / _OFFICIAL_DS[sk.name]
    opt = read_official_options(ds_dir / name / "opt.txt")
    vae_name = opt.get("vae_name")
    if not vae_name:
        raise ValueError(f"{ds_dir / name / 'opt.txt'} names no vae_name; is {name!r} a SALAD denoiser run?")
    vae_opt_path = ds_dir / str(vae_name) / "opt.txt"
    vae_opt = read_official_options(vae_opt_path) if vae_opt_path.is_file() else {}

    vae = load_official_checkpoint(ds_dir / str(vae_name) / "model" / f"{checkpoint}.tar", "vae", sk.name)
    act = vae_opt.get("activation", vae.config.activation)
    if act != vae.config.activation:       # not readable from the weights (MotionVAE.from_official_state_dict)
        vae = MotionVAE.from_official_state_dict(vae.official_state_dict(), sk.name, activation=act).eval()
    denoiser = load_official_checkpoint(ds_dir / name / "model" / f"{checkpoint}.tar", "denoiser")
    heads = int(opt.get("n_heads", denoiser.config.heads))
    den_act = opt.get("activation", denoiser.config.activation)
    den_act = den_act if den_act in ("gelu", "relu") else "gelu"   # official: anything but "relu" is GELU
    if heads != denoiser.config.heads or den_act != denoiser.config.activation:
        denoiser = Denoiser.from_official_state_dict(denoiser.official_state_dict(), heads=heads,
                                                     activation=den_act).eval()

    meta = Path(meta_dir) if meta_dir is not None else ds_dir / "Comp_v6_KLD005" / "meta"
    for f in ("mean.npy", "std.npy"):
        if not (meta / f).is_file():
            raise FileNotFoundError(f"normalisation statistics {meta / f} not found; pass meta_dir")
    mean, std = np.load(meta / "mean.npy"), np.load(meta / "std.npy")

    if text_encoder is None or isinstance(text_encoder, (str, os.PathLike)):
        if text_encoder is None:
            version = str(opt.get("clip_version", "ViT-B/32"))
            if version not in _CLIP_FOLDERS:
                raise ValueError(f"clip_version {version!r} in opt.txt; known: {sorted(_CLIP_FOLDERS)}")
            text_encoder = root / _CLIP_FOLDERS[version]
        text_encoder = load_text_encoder(text_encoder)
    base = DiffusionConfig()
    diffusion = DiffusionConfig(
        num_train_timesteps=int(opt.get("num_train_timesteps", base.num_train_timesteps)),
        beta_start=float(opt.get("beta_start", base.beta_start)), beta_end=float(opt.get("beta_end", base.beta_end)),
        beta_schedule=str(opt.get("beta_schedule", base.beta_schedule)),
        prediction_type=str(opt.get("prediction_type", base.prediction_type)))
    return SaladPipeline(vae, denoiser, text_encoder, mean, std, diffusion=diffusion, solver="ddim",
                         source=f"official SALAD {name}/{checkpoint} ({root})")


# ---------------------------------------------------------------------- faster evaluation
def length_groups(lengths: Sequence[int], groups: int) -> list[np.ndarray]:
    """Split a batch into at most ``groups`` groups of consecutive lengths with the least padding.

    Minimises ``sum over groups of (size x longest length)``, the frames a denoiser processes when
    each group is padded to its longest motion (exact dynamic programme over the sorted lengths).

    Returns
    -------
    list of int64 arrays
        Indices into ``lengths``; together they are a permutation of ``range(len(lengths))``.
    """
    lens = np.asarray(lengths, dtype=np.int64).reshape(-1)
    if lens.size == 0:
        raise ValueError("lengths is empty")
    if isinstance(groups, bool) or not isinstance(groups, (int, np.integer)) or groups < 1:
        raise ValueError(f"groups={groups!r} must be an int >= 1")
    order = np.argsort(lens, kind="stable")
    s = lens[order]
    n, k = len(s), min(int(groups), len(s))
    # cost[g][i]: least padded frames for the first i sorted items in g groups (a group [j, i) costs (i - j) * s[i-1])
    cost = np.full((k + 1, n + 1), np.inf)
    cut = np.zeros((k + 1, n + 1), dtype=np.int64)
    cost[0, 0] = 0.0
    for g in range(1, k + 1):
        for i in range(g, n + 1):
            j = np.arange(g - 1, i)
            c = cost[g - 1, j] + (i - j) * s[i - 1]
            best = int(np.argmin(c))
            cost[g, i], cut[g, i] = c[best], j[best]
    g = int(np.argmin(cost[1:, n])) + 1               # fewer groups when more do not help
    bounds, i = [], n
    while g > 0:
        j = int(cut[g, i])
        bounds.append((j, i))
        i, g = j, g - 1
    return [order[a:b] for a, b in reversed(bounds)]


@dataclass
class BucketedOutput:
    """What :class:`LengthBucketed` returns (the fields the protocol and the notebooks read)."""

    features: np.ndarray           # (B, max(lengths), D) raw features, zero past each length
    joints: list[np.ndarray]       # per sample (N_b, J, 3)
    texts: list[str]               # the prompts
    lengths: list[int]             # N_b


class LengthBucketed:
    """A SALAD generator that denoises each batch in groups of similar length.

    ``SaladPipeline`` pads a batch to its longest motion; in the T2M protocol's batches of 32
    random test items the longest is often twice the mean, so most of the work is padding.
    Grouping (:func:`length_groups`) removes most of it. Each sample keeps its own noise seed
    (``seed + b``, as the pipeline draws it) and padded frames are masked, so the motions equal
    those of one batched call up to floating-point reduction order.

    Parameters
    ----------
    pipe : SaladPipeline
        Or anything whose call takes per-sample seeds ``seed=[...]`` and returns ``features``,
        ``joints``, ``texts``, ``lengths``.
    groups : int
        Most calls per batch.
    """

    def __init__(self, pipe: Any, groups: int = 3) -> None:
        if isinstance(groups, bool) or not isinstance(groups, int) or groups < 1:
            raise ValueError(f"groups={groups!r} must be an int >= 1")
        self.pipe = pipe
        self.groups = groups
        self.source = getattr(pipe, "source", None)

    def __call__(self, prompts: Sequence[str], lengths: Sequence[int], seed: int | Sequence[int] = 0,
                 **kwargs: Any) -> BucketedOutput:
        prompts = [prompts] if isinstance(prompts, str) else list(prompts)
        if isinstance(lengths, (int, np.integer)):
            lengths = [int(lengths)] * len(prompts)
        lengths = [int(n) for n in lengths]
        if len(lengths) != len(prompts):
            raise ValueError(f"got {len(lengths)} lengths for {len(prompts)} prompts; give one length per prompt")
        if isinstance(seed, (int, np.integer)) and not isinstance(seed, bool):
            seeds = [int(seed) + b for b in range(len(prompts))]   # the pipeline's own per-sample rule
        else:
            seeds = [int(s) for s in seed]
            if len(seeds) != len(prompts):
                raise ValueError(f"got {len(seeds)} seeds for {len(prompts)} prompts")
        feats: np.ndarray | None = None
        joints: list[Any] = [None] * len(prompts)
        for idx in length_groups(lengths, self.groups):
            out = self.pipe([prompts[i] for i in idx], lengths=[lengths[i] for i in idx],
                            seed=[seeds[i] for i in idx], **kwargs)
            f = np.asarray(out.features)
            if feats is None:
                feats = np.zeros((len(prompts), max(lengths), f.shape[-1]), dtype=np.float32)
            for j, i in enumerate(idx):
                feats[i, : lengths[i]] = f[j, : lengths[i]]
                joints[i] = out.joints[j]
        return BucketedOutput(features=feats, joints=joints, texts=prompts, lengths=lengths)


# ---------------------------------------------------------------------------- KeyMotion
@dataclass(frozen=True)
class KeyframeRoundTrip:
    """A motion's own keyframes through the keyframe VAE (encode -> posterior mean -> decode)."""

    indices: np.ndarray            # (K,) int64 selected keyframe frames of the input
    decoded_indices: np.ndarray    # (K,) int64 frames the VAE decoded (positions -> frames)
    keyframes: np.ndarray          # (K, D) the selected keyframes, raw features
    decoded: np.ndarray            # (K, D) decoded keyframes, raw features, in decoded time order
    joints: np.ndarray             # (K, J, 3) each selected pose alone (root at the origin), metres
    decoded_joints: np.ndarray     # (K, J, 3) each decoded pose alone, metres
    pose_mpjpe: float              # root-aligned MPJPE between the two, metres
    index_error: float             # mean |decoded - selected| frame index, frames


@dataclass(frozen=True)
class Infilling:
    """A motion rebuilt by the MMAE from its own keyframes, and the linear-interpolation baseline."""

    indices: np.ndarray            # (K,) int64 keyframe frames given to the MMAE
    features: np.ndarray           # (N, D) in-filled motion, raw features
    joints: np.ndarray             # (N, J, 3) in-filled motion, metres
    lerp_joints: np.ndarray        # (N, J, 3) keyframes linearly interpolated (no model), metres
    true_joints: np.ndarray        # (N, J, 3) the input motion, metres
    mpjpe: float                   # MMAE vs input, root-aligned, metres
    mpjpe_global: float            # MMAE vs input, not root-aligned, metres
    lerp_mpjpe: float              # interpolation vs input, root-aligned, metres
    lerp_mpjpe_global: float       # interpolation vs input, not root-aligned, metres


def _keyframe_inputs(pipe, features: np.ndarray, method: str, num_keyframes: int | None):
    from salad_core.keymotion import select_keyframes

    x = np.asarray(features, dtype=np.float32)
    d = pipe.skeleton.feature_dim
    if x.ndim != 2 or x.shape[1] != d:
        raise ValueError(f"features must be one motion (N, {d}) of raw {pipe.skeleton.name} features, got {x.shape}")
    k = pipe.num_keyframes if num_keyframes is None else int(num_keyframes)
    if not k <= len(x) <= pipe.max_length:
        raise ValueError(f"the motion has {len(x)} frames; use {k} (keyframes) to {pipe.max_length} frames")
    norm = pipe.mmae.norm
    xn = norm.normalize(torch.from_numpy(x)).numpy()
    # selected on normalised features, as the keyframe VAE and MMAE were trained (keymotion.train)
    idx = select_keyframes(xn, k, method).astype(np.int64)
    return x, torch.from_numpy(xn)[None], torch.from_numpy(idx)[None]


@torch.no_grad()
def keyframe_roundtrip(pipe: "KeyMotionPipeline", features: np.ndarray, method: str = "mdo") -> KeyframeRoundTrip:
    """Select a motion's keyframes, encode them with KeyMotion's keyframe VAE and decode them.

    Parameters
    ----------
    pipe : KeyMotionPipeline
    features : array ``(N, D)``
        One motion, raw (de-normalised) features, ``K <= N <= pipe.max_length``.
    method : {"mdo", "mieo", "uniform"}
        Keyframe selection (KeyMotion §III-A; the models were trained on MDO keyframes).
    """
    from salad_core.eval.metrics import mpjpe
    from salad_core.keymotion.kf_vae import gather_keyframes, indices_to_positions
    from salad_core.keymotion.models import pose_joints
    from salad_core.keymotion.pipeline import decode_keyframes

    x, xn, idx = _keyframe_inputs(pipe, features, method, None)
    length = torch.tensor([len(x)])
    kf = gather_keyframes(xn, idx)                                        # (1, K, D) normalised
    enc = pipe.kf_vae.encode(kf, indices_to_positions(idx, length), sample=False)
    dec, dec_idx = decode_keyframes(pipe.kf_vae, enc.mu, length)
    norm = pipe.mmae.norm
    true_kf = norm.denormalize(kf)[0]
    dec_kf = norm.denormalize(dec)[0]
    tj = pose_joints(true_kf, pipe.skeleton).numpy()
    dj = pose_joints(dec_kf, pipe.skeleton).numpy()
    return KeyframeRoundTrip(indices=idx[0].numpy(), decoded_indices=dec_idx[0].numpy().astype(np.int64),
                             keyframes=true_kf.numpy(), decoded=dec_kf.numpy(), joints=tj, decoded_joints=dj,
                             pose_mpjpe=float(mpjpe(dj, tj)),
                             index_error=float(np.abs(dec_idx[0].numpy() - idx[0].numpy()).mean()))


@torch.no_grad()
def infill_from_keyframes(pipe: "KeyMotionPipeline", features: np.ndarray, caption: str, method: str = "mdo",
                          keep_keyframes: bool = False) -> Infilling:
    """Rebuild a motion from its own keyframes with KeyMotion's MMAE (text-conditioned in-filling).

    Parameters
    ----------
    pipe : KeyMotionPipeline
    features : array ``(N, D)``
        One motion, raw features, ``K <= N <= pipe.max_length``.
    caption : str
        Its caption (the MMAE is conditioned on text).
    method : {"mdo", "mieo", "uniform"}
        Keyframe selection.
    keep_keyframes : bool
        Paste the given keyframes over the MMAE's output at their frames.

    Returns
    -------
    Infilling
        The in-filled motion and its errors, beside per-channel linear interpolation of the same
        keyframes (:func:`~salad_core.keymotion.mmae.keyframe_lerp`), the floor the MMAE should beat.
    """
    from salad_core.eval.metrics import mpjpe
    from salad_core.keymotion.kf_vae import gather_keyframes
    from salad_core.keymotion.mmae import keyframe_lerp, scatter_keyframes
    from salad_core.motion import features_to_joints

    if not isinstance(caption, str) or not caption.strip():
        raise ValueError(f"caption={caption!r} must be a non-empty string")
    x, xn, idx = _keyframe_inputs(pipe, features, method, None)
    n = len(x)
    tb = pipe.text_encoder.encode([caption])
    dev = pipe.device
    out = pipe.mmae.infill(gather_keyframes(xn, idx).to(dev), idx.to(dev), torch.tensor([n], device=dev),
                           tb.features.to(dev), tb.mask.to(dev), keep_keyframes=keep_keyframes)
    canvas, mask = scatter_keyframes(gather_keyframes(xn, idx), idx, n)
    lerp = keyframe_lerp(canvas, mask)
    norm = pipe.mmae.norm
    feats = norm.denormalize(out.float().cpu())[0].numpy()
    lerp_feats = norm.denormalize(lerp)[0].numpy()
    sk = pipe.skeleton
    joints = features_to_joints(feats, sk).astype(np.float32)
    lerp_joints = features_to_joints(lerp_feats, sk).astype(np.float32)
    true_joints = features_to_joints(x, sk).astype(np.float32)
    return Infilling(indices=idx[0].numpy(), features=feats, joints=joints, lerp_joints=lerp_joints,
                     true_joints=true_joints, mpjpe=float(mpjpe(joints, true_joints)),
                     mpjpe_global=float(mpjpe(joints, true_joints, root_aligned=False)),
                     lerp_mpjpe=float(mpjpe(lerp_joints, true_joints)),
                     lerp_mpjpe_global=float(mpjpe(lerp_joints, true_joints, root_aligned=False)))
