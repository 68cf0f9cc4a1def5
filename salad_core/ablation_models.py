"""The shipped ablation models of paper Tables 2-3 and supplement Tables 2-4, and the study's reading of them.

``salad_core/weights/ablations`` (package data) holds small models trained on salad's procedural corpus, every
variant of a table with the same recipe and budget: ``vae_<name>/`` VAE folders, ``<name>/`` pipeline folders
(their VAE is the VAE variant's folder, not a copy; byte-identical normalisation statistics are stored once
and named by ``pipeline.json`` / ``index.json``), ``index.json``, the study's evaluation files
(``evaluations/<group>@<steps>.json``) and ``readings.json``, the study's reading: each paper table with our rows
and orderings at every evaluated stage, and each paper pair's verdict. Notebooks 06 and 07 load the models and
print the reading; how the study was run, and what was measured about each pair, is the lab's
(``lab/docs/ablations.md`` in a source checkout). Nothing here trains or measures.
"""
from __future__ import annotations

import os
from pathlib import Path
from typing import Any

__all__ = ["ablations_dir", "list_ablations", "load_ablation_pipeline", "load_ablation_vae", "load_readings",
           "READINGS_FILE"]

#: The study's reading, beside the models.
READINGS_FILE = "readings.json"


def ablations_dir() -> Path:
    """Folder of the shipped ablation models (package data)."""
    return Path(__file__).resolve().parent / "weights" / "ablations"


def list_ablations(root: str | os.PathLike | None = None) -> dict[str, dict[str, Any]]:
    """The shipped ablation models by folder name: ``{kind, label, table, vae, steps, ...}``.

    ``index.json`` is read as a weight folder's JSON (:func:`salad_core.limits.read_json`: size, UTF-8 and
    nesting checked before parsing); it must hold an object of objects (else ValueError / TypeError naming
    the file and the entry).
    """
    from salad_core import limits

    root = Path(root) if root is not None else ablations_dir()
    index = root / "index.json"
    if not index.is_file():
        raise FileNotFoundError(f"no ablation models in {root} (no index.json)")
    entries = limits.read_json(index, "ablation index")
    for name, entry in entries.items():
        if not isinstance(entry, dict):
            raise TypeError(f"{index}: entry {name!r} must be an object {{...}}, got {limits.short_json(entry)}")
    return entries


def load_ablation_pipeline(name: str, root: str | os.PathLike | None = None, *, text_encoder=None):
    """The :class:`~salad_core.pipeline.SaladPipeline` of a denoiser variant (e.g. ``"no_film"``)."""
    from salad_core.pipeline import SaladPipeline

    root = Path(root) if root is not None else ablations_dir()
    entries = list_ablations(root)
    if entries.get(name, {}).get("kind") != "denoiser":
        raise KeyError(f"{name!r} is not a shipped denoiser ablation; choose one of "
                       f"{sorted(k for k, e in entries.items() if e['kind'] == 'denoiser')}")
    # the variants share VAEs and statistics with their siblings in root ("vae": "../vae_st_long/vae")
    return SaladPipeline.from_pretrained(root / name, text_encoder=text_encoder, allow_outside_paths=root)


def load_ablation_vae(name: str, root: str | os.PathLike | None = None, *,
                      allow_outside_paths: bool | str | os.PathLike = False):
    """``(vae, mean, std)`` of a VAE variant (``"st"``, ``"pose"``, ``"no_pos"`` ... or ``"vae_st"``).

    ``mean``/``std`` are ``(D,)`` float32 numpy arrays: the normalisation the VAE was trained with.

    The statistics file an ``index.json`` entry names (``"stats"``) and the VAE's checkpoint files must lie
    inside ``root`` after ``..`` and symbolic links are resolved (:func:`salad_core.limits.resolve_inside`);
    ``allow_outside_paths=True`` accepts any place, a folder that folder too. Otherwise ValueError naming the
    entry, the key and where it leads.
    """
    from salad_core import limits
    from salad_core.io import checkpoint_files, load_model, load_tensors

    root = Path(root) if root is not None else ablations_dir()
    index = root / "index.json"
    entries = list_ablations(root)
    folder = name if name.startswith("vae_") else f"vae_{name}"
    if entries.get(folder, {}).get("kind") != "vae":
        raise KeyError(f"{name!r} is not a shipped VAE ablation; choose one of "
                       f"{sorted(str(e.get('variant')) for e in entries.values() if e.get('kind') == 'vae')}")
    # identical statistics are stored once: the entry names the file it shares (else the folder's own)
    stats_path = limits.resolve_inside(root, entries[folder].get("stats", f"{folder}/stats.safetensors"), "stats",
                                       f"{index}: {folder!r}", allow_outside_paths)
    stem = root / folder / "vae"
    for file in checkpoint_files(stem):         # a symbolic link may leave the folder
        limits.check_inside(root, file, "vae", f"{folder}/vae", f"{index}: {folder!r}", allow_outside_paths)
    vae, _, _ = load_model(stem)
    stats = load_tensors(stats_path)
    if "mean" not in stats or "std" not in stats:
        raise ValueError(f"{stats_path} (named by {index}: {folder!r}) lacks 'mean' or 'std' (it holds "
                         f"{sorted(stats)})")
    mean, std = stats["mean"].float().numpy(), stats["std"].float().numpy()
    limits.check_stats(mean, std, str(stats_path))
    return vae, mean, std


def load_readings(root: str | os.PathLike | None = None) -> dict[str, Any]:
    """The study's reading (``readings.json``), read and returned as it is stored:

    * ``tables``: paper table (``"table2"``, ``"supp_table4"``, ``"table3"``, ``"supp_table2"``, ``"supp_table3"``)
      -> Markdown: our rows at the final stage (95 % intervals, the paper's figures apart) and every paper pair's
      ordering at each evaluated stage (``>`` the first row better, ``<`` worse, ``=`` level);
    * ``verdicts``: group (``"vaes"``, ``"denoisers"``) -> Markdown, one row per paper pair and metric with the
      verdict (``reproduced``, ``reproduced, paired only``, ``level``, ``reversed``) and what was measured about it;
    * ``pairs``: the same verdicts as records (``table``, ``pair``, ``metric``, ``paper``, ``ours``, ``verdict``,
      ``read_at``);
    * ``made_by``: the command that wrote the file, and ``report``: where the lab's report is.
    """
    root = Path(root) if root is not None else ablations_dir()
    path = root / READINGS_FILE
    if not path.is_file():
        raise FileNotFoundError(f"{path} is missing: the ablation models ship with their reading")
    from salad_core import limits

    return limits.read_json(path, "study reading")      # size, UTF-8 and nesting checked before parsing
