"""VAE posteriors of every training window, computed once per (VAE, corpus) and kept on disk.

A latent-diffusion step needs ``z = mu + eps * exp(logvar / 2)`` of its motions under a *frozen*
VAE. ``mu`` and ``logvar`` depend only on the VAE's weights and the window of the clip the item
returns (``MotionTextDataset.crops``: every ``(motion_id, offset, length)`` an item can take), so
they are encoded once, in batches of equal-length windows, and stored; a training step then looks
them up and still draws ``eps`` per step (the reparameterised sampling is unchanged).

Windows are cached per crop offset, not as one posterior per clip cropped in latent space: the
encoder's convolutions see zero padding at a window's edges and its pooling groups frames from the
window's first frame, so a window's latents are not a slice of the clip's (the crops start at any
frame, not only at multiples of 4).

Layout of a cache folder (``<cache_dir>/<signature>/``)::

    index.json        format, signature, what it was built from, keys and their first row / row count
    mu.npy, logvar.npy  (rows, *row_shape) arrays (float32 by default), memory-mapped when read

The signature hashes the VAE's weights (:func:`module_digest`), the corpus (:func:`corpus_digest`:
the clip files' names, sizes and modification times, the normalisation statistics and the crop
settings), the encoding mode and the format; change one weight or touch one clip file and a new
folder is built. The folder is written under a temporary name and renamed, so a reader never sees
half a cache.
"""
from __future__ import annotations

import contextlib
import hashlib
import json
import logging
import os
import shutil
import time
from pathlib import Path
from typing import Any, Callable, Iterable, Iterator, Sequence

import numpy as np
import torch

__all__ = ["CACHE_FORMAT", "Key", "module_digest", "corpus_digest", "LatentCache", "build_latent_cache",
           "open_or_build", "open_or_build_shared", "encode_motion_windows"]

log = logging.getLogger(__name__)

CACHE_FORMAT = "salad-latent-cache/1"
Key = tuple  # (motion_id: str, offset: int, length: int)
_DTYPES = {"float32": np.float32, "float16": np.float16}


def module_digest(module: torch.nn.Module) -> str:
    """SHA-256 of a module's state (names, dtypes, shapes and bytes of every tensor), hex."""
    h = hashlib.sha256()
    for name, tensor in sorted(module.state_dict().items()):
        t = tensor.detach().cpu().contiguous()
        h.update(f"{name}|{t.dtype}|{tuple(t.shape)}|".encode())
        h.update(t.view(torch.uint8).numpy().tobytes() if t.numel() else b"")
    return h.hexdigest()


def corpus_digest(dataset: Any) -> str:
    """SHA-256 of what a :class:`~salad_core.data.dataset.MotionTextDataset`'s windows are made of.

    Cheap (no file is read): the clip files' names, sizes and modification times
    (``new_joint_vecs/<id>.npy``), the normalisation statistics, the split's windows
    (``dataset.crops()``) and the normalise flag. Touching a clip file changes it.
    """
    h = hashlib.sha256()
    root = Path(dataset.root)
    clips = sorted({k[0] for k in dataset.crops()})
    for mid in clips:
        st = (root / "new_joint_vecs" / f"{mid}.npy").stat()
        h.update(f"{mid}|{st.st_size}|{st.st_mtime_ns}\n".encode())
    for arr in (dataset.mean, dataset.std):
        h.update(b"none" if arr is None else np.ascontiguousarray(arr, dtype=np.float32).tobytes())
    h.update(json.dumps([list(k) for k in dataset.crops()]).encode())
    h.update(f"normalize={getattr(dataset, 'normalize', True)}".encode())
    return h.hexdigest()


class LatentCache:
    """Read side of a cache folder: ``(mu, logvar)`` rows per window key.

    Parameters
    ----------
    folder : path
        A folder written by :func:`build_latent_cache`.
    """

    def __init__(self, folder: str | os.PathLike) -> None:
        self.folder = Path(folder)
        doc = json.loads((self.folder / "index.json").read_text())
        if doc.get("format") != CACHE_FORMAT:
            raise ValueError(f"{self.folder} is not a latent cache of format {CACHE_FORMAT!r} "
                             f"(found {doc.get('format')!r})")
        self.signature: str = doc["signature"]
        self.meta: dict[str, Any] = doc.get("meta", {})
        self.row_shape = tuple(doc["row_shape"])
        self._index = {tuple(k): (int(s), int(n)) for k, s, n in doc["keys"]}
        self.mu = np.load(self.folder / "mu.npy", mmap_mode="r")
        self.logvar = np.load(self.folder / "logvar.npy", mmap_mode="r")

    def __len__(self) -> int:
        return len(self._index)

    def __contains__(self, key: Key) -> bool:
        return tuple(key) in self._index

    def rows(self, key: Key) -> tuple[np.ndarray, np.ndarray]:
        """``(mu, logvar)`` of one window, each ``(rows, *row_shape)`` (views of the memory map)."""
        try:
            start, count = self._index[tuple(key)]
        except KeyError:
            raise KeyError(f"window {tuple(key)} is not in the latent cache {self.folder}") from None
        return self.mu[start:start + count], self.logvar[start:start + count]

    def lookup(self, keys: Sequence[Key], rows: int | None = None) -> tuple[torch.Tensor, torch.Tensor]:
        """``(mu, logvar)`` float32 tensors ``(B, rows, *row_shape)`` of ``keys``, zero past each window's rows.

        ``rows`` defaults to the largest row count among ``keys``; windows with more rows are cut.
        """
        found = [self.rows(k) for k in keys]
        rows = max(m.shape[0] for m, _ in found) if rows is None else rows
        mu = np.zeros((len(keys), rows, *self.row_shape), dtype=np.float32)
        logvar = np.zeros_like(mu)
        for i, (m, lv) in enumerate(found):
            n = min(rows, m.shape[0])
            mu[i, :n] = m[:n]
            logvar[i, :n] = lv[:n]
        return torch.from_numpy(mu), torch.from_numpy(logvar)


def build_latent_cache(folder: str | os.PathLike, signature: str, keys: Sequence[Key], row_counts: Sequence[int],
                       row_shape: Sequence[int], batches: Iterable[tuple[Sequence[int], torch.Tensor, torch.Tensor]],
                       *, dtype: str = "float32", meta: dict[str, Any] | None = None) -> LatentCache:
    """Write a cache folder atomically and open it.

    Parameters
    ----------
    folder : path
        The cache folder to create (``<cache_dir>/<signature>``); replaced if it exists.
    signature : str
        Stored in ``index.json`` (and checked by :func:`open_or_build`).
    keys : sequence of hashable tuples ``(n,)``
        Window keys (JSON-serialisable items).
    row_counts : sequence of int ``(n,)``
        Rows of each key's posterior (e.g. latent frames).
    row_shape : sequence of int
        Shape of one row (e.g. ``(parts, latent_dim)``).
    batches : iterable of ``(key indices, mu, logvar)``
        ``mu``/``logvar`` ``(len(indices), >= rows, *row_shape)``; every key must be covered once.
    dtype : {"float32", "float16"}
        Storage dtype (float16 halves the size; posteriors then differ by up to ~5e-4 relative).
    meta : dict, optional
        Stored in ``index.json`` (what the cache was built from).
    """
    if dtype not in _DTYPES:
        raise ValueError(f"dtype={dtype!r} is invalid; use one of {sorted(_DTYPES)}")
    if len(keys) != len(row_counts):
        raise ValueError(f"{len(keys)} keys but {len(row_counts)} row counts")
    folder = Path(folder)
    folder.parent.mkdir(parents=True, exist_ok=True)
    tmp = folder.parent / f".{folder.name}.tmp-{os.getpid()}"
    shutil.rmtree(tmp, ignore_errors=True)
    tmp.mkdir()
    starts = np.concatenate([[0], np.cumsum(np.asarray(row_counts, dtype=np.int64))])
    total = int(starts[-1])
    shape = (total, *row_shape)
    mu_out = np.lib.format.open_memmap(tmp / "mu.npy", mode="w+", dtype=_DTYPES[dtype], shape=shape)
    lv_out = np.lib.format.open_memmap(tmp / "logvar.npy", mode="w+", dtype=_DTYPES[dtype], shape=shape)
    done = np.zeros(len(keys), dtype=bool)
    for idx, mu, logvar in batches:
        mu, logvar = mu.detach().cpu().float().numpy(), logvar.detach().cpu().float().numpy()
        for j, i in enumerate(idx):
            s, n = int(starts[i]), int(row_counts[i])
            mu_out[s:s + n] = mu[j, :n]
            lv_out[s:s + n] = logvar[j, :n]
            done[i] = True
    if not done.all():
        shutil.rmtree(tmp, ignore_errors=True)
        raise RuntimeError(f"{int((~done).sum())} of {len(keys)} windows were not encoded; the cache is not written")
    mu_out.flush()
    lv_out.flush()
    del mu_out, lv_out
    doc = {"format": CACHE_FORMAT, "signature": signature, "meta": meta or {}, "row_shape": list(row_shape),
           "dtype": dtype, "keys": [[list(k), int(starts[i]), int(row_counts[i])] for i, k in enumerate(keys)]}
    (tmp / "index.json").write_text(json.dumps(doc) + "\n")
    if folder.exists():
        shutil.rmtree(folder)
    os.replace(tmp, folder)
    return LatentCache(folder)


def open_or_build(cache_dir: str | os.PathLike, signature: str, build: Callable[[Path], LatentCache], *,
                  prune: bool = False) -> LatentCache:
    """The cache ``<cache_dir>/<signature>``, built with ``build(folder)`` when it is missing or unreadable.

    ``prune`` removes the folder's other caches (built from other VAE weights or another corpus).

    Processes that share ``cache_dir`` (the ablation study's denoisers on one VAE, trained side by side)
    take an exclusive lock on ``<cache_dir>/.<signature>.lock`` first: one builds, the others wait and
    then reuse its cache instead of encoding the same windows again.
    """
    cache_dir = Path(cache_dir)
    cache_dir.mkdir(parents=True, exist_ok=True)
    with _exclusive(cache_dir / f".{signature[:32]}.lock"):
        return _open_or_build(cache_dir, signature, build, prune)


@contextlib.contextmanager
def _exclusive(lock_path: Path) -> Iterator[None]:
    """An exclusive advisory lock on ``lock_path`` (POSIX ``flock``; no lock where ``fcntl`` is missing)."""
    try:
        import fcntl
    except ImportError:              # Windows: processes do not share run folders there
        yield
        return
    with open(lock_path, "a") as fh:
        fcntl.flock(fh, fcntl.LOCK_EX)
        try:
            yield
        finally:
            fcntl.flock(fh, fcntl.LOCK_UN)


def _open_or_build(cache_dir: Path, signature: str, build: Callable[[Path], LatentCache], prune: bool) -> LatentCache:
    folder = cache_dir / signature[:32]
    try:
        cache = LatentCache(folder)
        if cache.signature == signature:
            log.info("latent cache %s: %d windows (reused)", folder, len(cache))
            return cache
        log.warning("latent cache %s has another signature; rebuilding", folder)
    except (OSError, ValueError, KeyError, json.JSONDecodeError):
        pass
    if prune and cache_dir.is_dir():
        for other in cache_dir.iterdir():
            if other.is_dir() and other.name != folder.name and (other / "index.json").is_file():
                log.info("removing the stale latent cache %s", other)
                shutil.rmtree(other, ignore_errors=True)
    t0 = time.perf_counter()
    cache = build(folder)
    log.info("latent cache %s: %d windows encoded in %.1f s", folder, len(cache), time.perf_counter() - t0)
    return cache


def open_or_build_shared(cache_dir: str | os.PathLike, signature: str, build: Callable[[Path], LatentCache],
                         env: Any, *, prune: bool = False) -> LatentCache:
    """:func:`open_or_build` under ``torchrun``: rank 0 opens or builds, the others wait, then open it."""
    from .distributed import barrier

    cache = open_or_build(cache_dir, signature, build, prune=prune) if env.is_main else None
    barrier(env)
    return cache if cache is not None else open_or_build(cache_dir, signature, build)


def encode_motion_windows(vae: torch.nn.Module, features: Callable[[Key], np.ndarray], keys: Sequence[Key],
                          *, pad_to: int | None = None, batch_frames: int = 2560
                          ) -> Iterator[tuple[list[int], torch.Tensor, torch.Tensor]]:
    """Posteriors of motion windows under a skeleto-temporal VAE, in batches of equal-length windows.

    Parameters
    ----------
    vae : MotionVAE
        In eval mode (no dropout); ``encode(x, sample=False)``.
    features : callable
        ``key -> (length, D)`` normalised features of the window.
    keys : sequence of ``(motion_id, offset, length)``
    pad_to : int, optional
        Encode every window zero-padded to this many frames (the trainer's ``vae_pad_to_max``) and
        keep its first ``length // downsample`` latent frames; None: encode the window alone.
    batch_frames : int
        Frames per encoder call (windows of one length are grouped up to this budget).

    Yields
    ------
    (key indices, mu, logvar)
        ``mu``/``logvar`` ``(len(indices), length // downsample, P, Dz)``.
    """
    ds = vae.downsample
    by_length: dict[int, list[int]] = {}
    for i, k in enumerate(keys):
        if int(k[2]) % ds:
            raise ValueError(f"window {tuple(k)} has a length that is not a multiple of the VAE's down-sampling {ds}")
        by_length.setdefault(int(k[2]), []).append(i)
    device = next(vae.parameters()).device
    for length in sorted(by_length):
        n_frames = pad_to if pad_to is not None else length
        if n_frames < length:
            raise ValueError(f"pad_to={pad_to} is shorter than a window of {length} frames")
        per_call = max(1, batch_frames // n_frames)
        group = by_length[length]
        for b0 in range(0, len(group), per_call):
            idx = group[b0: b0 + per_call]
            x = np.zeros((len(idx), n_frames, vae.feature_dim), dtype=np.float32)
            for j, i in enumerate(idx):
                x[j, :length] = features(keys[i])
            with torch.no_grad():
                enc = vae.encode(torch.from_numpy(x).to(device), sample=False)
            n_lat = length // ds
            yield idx, enc.mu[:, :n_lat], enc.logvar[:, :n_lat]
