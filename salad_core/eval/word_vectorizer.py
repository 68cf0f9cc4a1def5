"""Word/POS tokens -> word vectors and POS one-hots, the text input of the T2M evaluator.

A caption reaches the evaluator as HumanML3D ``word/POS`` tokens (``texts/*.txt``, second field).
Each token becomes a word vector (GloVe 300-d for the official evaluator) and a 15-d one-hot over
the POS enumerator, in which 5 "VIP" word lists (locations, body parts, objects, actions,
descriptors) override the spaCy tag (Guo et al. 2022, ``humanml3d_eval_facts`` §4.1). A caption is
cropped to ``max_text_len`` tokens, wrapped in ``sos``/``eos`` and padded with ``unk`` to
``max_text_len + 2`` rows (§3.4).

Two ways to build a :class:`WordVectorizer`:

- :meth:`WordVectorizer.from_glove` reads the official GloVe folder (``our_vab_data.npy``,
  ``our_vab_words.pkl``, ``our_vab_idx.pkl``). The two pickles are plain lists/dicts; they are read
  with :func:`load_plain_pickle`, which refuses anything but a few builtin container and scalar
  types, so a tampered file cannot run code.
- ``WordVectorizer(words, vectors)`` from an in-memory vocabulary and vector matrix (for our own
  evaluator: vectors derived from a sentence encoder, or learned).
"""
from __future__ import annotations

import io
import logging
import pickle
from os import PathLike
from pathlib import Path
from typing import Mapping, Sequence

import numpy as np

__all__ = [
    "POS_ENUMERATOR",
    "VIP_LISTS",
    "SOS",
    "EOS",
    "UNK",
    "WordVectorizer",
    "load_plain_pickle",
    "UnsafePickleError",
]

logger = logging.getLogger(__name__)

#: POS one-hot positions (T2M ``utils/word_vectorizer.py``): 9 spaCy coarse tags, 5 VIP classes, OTHER.
POS_ENUMERATOR: dict[str, int] = {
    "VERB": 0, "NOUN": 1, "DET": 2, "ADP": 3, "NUM": 4, "AUX": 5, "PRON": 6, "ADJ": 7, "ADV": 8,
    "Loc_VIP": 9, "Body_VIP": 10, "Obj_VIP": 11, "Act_VIP": 12, "Desc_VIP": 13, "OTHER": 14,
}
NUM_POS = len(POS_ENUMERATOR)

#: VIP word lists, in the order they are checked (a word's first matching list wins).
VIP_LISTS: dict[str, frozenset[str]] = {
    "Loc_VIP": frozenset(("left", "right", "clockwise", "counterclockwise", "anticlockwise", "forward",
                          "back", "backward", "up", "down", "straight", "curve")),
    "Body_VIP": frozenset(("arm", "chin", "foot", "feet", "face", "hand", "mouth", "leg", "waist", "eye",
                           "knee", "shoulder", "thigh")),
    "Obj_VIP": frozenset(("stair", "dumbbell", "chair", "window", "floor", "car", "ball", "handrail",
                          "baseball", "basketball")),
    "Act_VIP": frozenset(("walk", "run", "swing", "pick", "bring", "kick", "put", "squat", "throw", "hop",
                          "dance", "jump", "turn", "stumble", "stop", "sit", "lift", "lower", "raise",
                          "wash", "stand", "kneel", "stroll", "rub", "bend", "balance", "flap", "jog",
                          "shuffle", "lean", "rotate", "spin", "spread", "climb")),
    "Desc_VIP": frozenset(("slowly", "carefully", "fast", "careful", "slow", "quickly", "happy", "angry",
                           "sad", "happily", "angrily", "sadly")),
}

#: Special words every vocabulary must contain (rows 0, 1, 2 of the official GloVe table).
SOS, EOS, UNK = "sos", "eos", "unk"
_OTHER = "OTHER"


class UnsafePickleError(pickle.UnpicklingError):
    """A pickle referenced a global (class or function) outside the allowed builtin types."""


# Only inert builtin types: never callables such as eval, getattr or __import__.
_ALLOWED_GLOBALS: frozenset[tuple[str, str]] = frozenset(
    ("builtins", name) for name in
    ("list", "dict", "tuple", "set", "frozenset", "str", "bytes", "bytearray", "int", "float", "bool",
     "complex")
)


class _PlainUnpickler(pickle.Unpickler):
    def find_class(self, module: str, name: str):  # noqa: D102 (pickle hook)
        if module == "__builtin__":  # Python 2 pickles name the builtins module so
            module = "builtins"
        if (module, name) in _ALLOWED_GLOBALS:
            return super().find_class(module, name)
        raise UnsafePickleError(
            f"pickle references {module}.{name}; only plain builtin data "
            f"({', '.join(sorted(n for _, n in _ALLOWED_GLOBALS))}) may be loaded")


def load_plain_pickle(path: str | PathLike) -> object:
    """Unpickle a file that may only hold builtin data (lists, dicts, str, int, float, ...).

    Any reference to another class or function (which is how a malicious pickle runs code)
    raises :class:`UnsafePickleError` before anything is called.
    """
    data = Path(path).read_bytes()
    return _PlainUnpickler(io.BytesIO(data), encoding="latin1").load()


class WordVectorizer:
    """Map ``word/POS`` tokens to word vectors and POS one-hots (T2M text input).

    Parameters
    ----------
    words : sequence of str, length V
        The vocabulary; row ``i`` of ``vectors`` belongs to ``words[i]``. Must contain
        ``"sos"``, ``"eos"`` and ``"unk"``, and no duplicates.
    vectors : array ``(V, d)``
        Word vectors (GloVe: ``d = 300``). Stored as float32.
    max_text_len : int
        Tokens kept per caption before ``sos``/``eos`` are added (T2M: 20).
    """

    def __init__(self, words: Sequence[str], vectors: np.ndarray, max_text_len: int = 20) -> None:
        vectors = np.asarray(vectors, dtype=np.float32)
        words = tuple(words)
        if vectors.ndim != 2 or vectors.shape[0] != len(words):
            raise ValueError(f"vectors must have shape (len(words)={len(words)}, d), got {vectors.shape}")
        if not all(isinstance(w, str) for w in words):
            raise TypeError("words must all be str")
        index = {w: i for i, w in enumerate(words)}
        if len(index) != len(words):
            dup = next(w for i, w in enumerate(words) if index[w] != i)
            raise ValueError(f"words contains duplicates, e.g. {dup!r}")
        missing = [w for w in (SOS, EOS, UNK) if w not in index]
        if missing:
            raise ValueError(f"the vocabulary must contain the special words {missing} (sos, eos, unk)")
        if not np.isfinite(vectors).all():
            raise ValueError("vectors contains NaN or inf")
        if not isinstance(max_text_len, int) or max_text_len < 1:
            raise ValueError(f"max_text_len must be a positive int, got {max_text_len!r}")
        self.words = words
        self.vectors = vectors
        self.max_text_len = max_text_len
        self._index = index

    # ----------------------------------------------------------- construction
    @classmethod
    def from_glove(cls, folder: str | PathLike, prefix: str = "our_vab",
                   max_text_len: int = 20) -> "WordVectorizer":
        """Read the official GloVe folder: ``{prefix}_data.npy`` ``(V, 300)``, ``{prefix}_words.pkl``
        (list of V words) and ``{prefix}_idx.pkl`` (word -> row), the pickles via
        :func:`load_plain_pickle`."""
        folder = Path(folder)
        paths = {k: folder / f"{prefix}_{k}" for k in ("data.npy", "words.pkl", "idx.pkl")}
        for p in paths.values():
            if not p.is_file():
                raise FileNotFoundError(f"GloVe file not found: {p} (expected {prefix}_data.npy, "
                                        f"{prefix}_words.pkl and {prefix}_idx.pkl in {folder})")
        from salad_core import limits

        table = limits.read_npy(paths["data.npy"], kinds="f")   # header checked before the data
        words = load_plain_pickle(paths["words.pkl"])
        word2idx = load_plain_pickle(paths["idx.pkl"])
        if not isinstance(words, (list, tuple)) or not all(isinstance(w, str) for w in words):
            raise ValueError(f"{paths['words.pkl']} must hold a list of str, got {type(words).__name__}")
        if not isinstance(word2idx, Mapping):
            raise ValueError(f"{paths['idx.pkl']} must hold a dict word -> row, got {type(word2idx).__name__}")
        if table.ndim != 2:
            raise ValueError(f"{paths['data.npy']} must be 2-D (V, d), got shape {table.shape}")
        rows = []
        for w in words:
            i = word2idx.get(w)
            if not isinstance(i, int) or not 0 <= i < table.shape[0]:
                raise ValueError(f"{paths['idx.pkl']}: word {w!r} has row {i!r}, not in [0, {table.shape[0]})")
            rows.append(i)
        logger.info("loaded GloVe vocabulary of %d words (%d-d) from %s", len(words), table.shape[1], folder)
        return cls(words, table[rows], max_text_len=max_text_len)

    # --------------------------------------------------------------- queries
    @property
    def dim(self) -> int:
        """Word-vector width ``d``."""
        return int(self.vectors.shape[1])

    @property
    def padded_len(self) -> int:
        """Rows per processed caption: ``max_text_len + 2`` (sos and eos)."""
        return self.max_text_len + 2

    def __len__(self) -> int:
        return len(self.words)

    def __contains__(self, word: str) -> bool:
        return word in self._index

    @staticmethod
    def pos_index(word: str, pos: str) -> int:
        """POS one-hot position of an in-vocabulary word: its VIP class if any, else its tag, else OTHER."""
        for vip, members in VIP_LISTS.items():
            if word in members:
                return POS_ENUMERATOR[vip]
        return POS_ENUMERATOR.get(pos, POS_ENUMERATOR[_OTHER])

    def lookup(self, token: str) -> tuple[np.ndarray, int]:
        """``"word/POS"`` -> (word vector ``(d,)``, POS index). Out-of-vocabulary words get the
        ``unk`` vector and OTHER."""
        word, sep, pos = token.rpartition("/")
        if not sep or not word:
            raise ValueError(f"token {token!r} is not of the form word/POS")
        i = self._index.get(word)
        if i is None:
            return self.vectors[self._index[UNK]], POS_ENUMERATOR[_OTHER]
        return self.vectors[i], self.pos_index(word, pos)

    def process_tokens(self, tokens: Sequence[str]) -> tuple[np.ndarray, np.ndarray, int]:
        """One caption's evaluator input.

        Parameters
        ----------
        tokens : sequence of str
            ``word/POS`` tokens of one caption (any length; more than ``max_text_len`` are cropped).

        Returns
        -------
        word_embs : float32 array ``(L, d)``
            ``L = max_text_len + 2``: ``sos``, the tokens, ``eos``, then ``unk`` padding.
        pos_ohot : float32 array ``(L, 15)``
            POS one-hots on the same rows (``sos``/``eos``/padding are OTHER).
        sent_len : int
            Rows before the padding: ``min(n, max_text_len) + 2``.
        """
        if isinstance(tokens, str):
            raise TypeError("tokens must be a sequence of 'word/POS' strings, not one string")
        body = list(tokens[: self.max_text_len])
        seq = [f"{SOS}/{_OTHER}", *body, f"{EOS}/{_OTHER}"]
        sent_len = len(seq)
        seq += [f"{UNK}/{_OTHER}"] * (self.padded_len - sent_len)
        word_embs = np.empty((len(seq), self.dim), dtype=np.float32)
        pos_ohot = np.zeros((len(seq), NUM_POS), dtype=np.float32)
        for row, tok in enumerate(seq):
            vec, p = self.lookup(tok)
            word_embs[row] = vec
            pos_ohot[row, p] = 1.0
        return word_embs, pos_ohot, sent_len

    def process_batch(self, captions: Sequence[Sequence[str]]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """:meth:`process_tokens` over B captions, stacked: ``(B, L, d)``, ``(B, L, 15)``, ``(B,)`` int64."""
        if len(captions) == 0:
            raise ValueError("captions is empty")
        out = [self.process_tokens(c) for c in captions]
        return (np.stack([o[0] for o in out]), np.stack([o[1] for o in out]),
                np.array([o[2] for o in out], dtype=np.int64))
