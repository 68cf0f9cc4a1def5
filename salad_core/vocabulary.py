"""What a model was trained to read: the training vocabulary of a set of weights, and prompt checks.

The shipped models learned from the procedural corpus's captions only. A word that never occurred
in them (``"cartwheel"``) is still encoded by the text encoder (MiniLM knows it), but the denoiser
never learned what motion goes with it, so the motion ignores it: a cartwheel stands upright. Text in
another script or emoji is worse: the encoder turns much of it into ``[UNK]`` tokens, which carry
nothing at all. This module lets the pipelines say so instead of failing silently.

* :func:`training_vocabulary` reads a corpus folder (HumanML3D layout, ``texts/<id>.txt`` and
  ``train.txt``) and returns the sorted word forms of its training captions, as
  :func:`salad_core.data.texts.split_words` cuts them (lower-case ``[a-z]+`` runs: the same words
  the attention maps and edits use).
* :func:`write_vocabulary` / :func:`load_vocabulary` store it as ``vocabulary.json`` in a weights folder.
* :func:`check_prompt` compares a prompt with a vocabulary and :func:`describe_unknown` says it in
  one line; the pipelines warn with :class:`UnknownWordsWarning`.

The shipped files were made with::

    python -m salad_core.cli corpus build --out CORPUS --size default --seed 0   # with the code of the weights' commit
    python -m salad_core.vocabulary CORPUS --out salad_core/weights/<model> --corpus-version 2.x --commit C
"""
from __future__ import annotations

import json
import logging
import re
import unicodedata
from dataclasses import dataclass, field
from pathlib import Path
from typing import Iterable, Sequence

from salad_core.data.texts import parse_text_line, split_words

__all__ = ["UnknownWordsWarning", "VOCABULARY_FILE", "FUNCTION_WORDS", "PromptCheck", "training_vocabulary",
           "write_vocabulary", "load_vocabulary", "vocabulary_info", "vocabulary_and_source", "check_prompt",
           "describe_unknown", "unknown_words_message", "UNK_TOKENS"]

#: File name of a weights folder's vocabulary.
VOCABULARY_FILE = "vocabulary.json"
#: Words that name no motion and no body part (articles, pronouns, the subject, light verbs): not
#: counted when deciding whether a prompt is mostly unknown, so "a person does a cartwheel" is.
FUNCTION_WORDS = frozenset(
    "a an the and then while his her their its is are was be being to of in on at up with as by for from into "
    "he she they it them him this that someone somebody person man woman people human actor figure guy "
    "does do doing did performs perform performing makes make making".split())
#: Token strings of "unknown" in the encoders salad supports (BERT/MiniLM and CLIP).
UNK_TOKENS = frozenset({"[UNK]", "<unk>", "<|unk|>"})
#: Share of content terms above which a prompt is "mostly unknown".
MOSTLY_UNKNOWN = 0.5

_WORD_RE = re.compile(r"[a-z]+")


class UnknownWordsWarning(UserWarning):
    """A prompt holds words the model never saw in training (or text the encoder cannot read at all).

    The motion is generated anyway, but those words do not steer it. Silence it with
    ``warnings.filterwarnings("ignore", category=UnknownWordsWarning)``.
    """


# ----------------------------------------------------------------------------------- building
def training_vocabulary(corpus_dir: str | Path, split: str = "train") -> list[str]:
    """Sorted distinct words of the captions of a corpus split (``split_words`` convention).

    Parameters
    ----------
    corpus_dir : path
        A corpus in HumanML3D layout (``texts/<id>.txt``, ``<split>.txt``), e.g. built by
        ``salad corpus build --out DIR --size default --seed 0``.
    split : str
        Which split's captions (``"train"``: what the models learned from; ``"all"`` for every clip).

    Returns
    -------
    list of str
    """
    root = Path(corpus_dir)
    ids_file = root / f"{split}.txt"
    if not ids_file.is_file():
        raise FileNotFoundError(f"{ids_file} does not exist: {root} is not a corpus folder with a {split!r} split")
    words: set[str] = set()
    for clip in ids_file.read_text().split():
        path = root / "texts" / f"{clip}.txt"
        if not path.is_file():
            raise FileNotFoundError(f"{path} is missing: clip {clip} of {ids_file.name} has no captions")
        for k, line in enumerate(path.read_text(encoding="utf-8").splitlines()):
            if line.strip():
                words.update(split_words(parse_text_line(line, f"{path}:{k + 1}").caption))
    return sorted(words)


def write_vocabulary(words: Iterable[str], weights_dir: str | Path, **info) -> Path:
    """Write ``vocabulary.json`` (``{"words": [...], "n_words": n, **info}``) into ``weights_dir``."""
    from salad_core.io import atomic_write_text

    words = sorted(set(words))
    bad = [w for w in words if not _WORD_RE.fullmatch(w)]
    if bad:
        raise ValueError(f"vocabulary words must be lower-case a-z runs (split_words), got {bad[:5]}")
    doc = dict(info, n_words=len(words), words=words)
    path = Path(weights_dir) / VOCABULARY_FILE
    return atomic_write_text(path, json.dumps(doc, indent=1) + "\n")


def vocabulary_info(weights_dir: str | Path, allow_outside_paths: bool | str | Path = False) -> dict | None:
    """The whole ``vocabulary.json`` of a weights folder (words and provenance), or None without one.

    The file must lie inside ``weights_dir`` after symbolic links are resolved (as every file a weight folder
    names, :func:`salad_core.limits.check_inside`): a ``vocabulary.json`` that links elsewhere raises
    ValueError naming where it leads, unless ``allow_outside_paths`` (True: any place; a folder: that one too).
    """
    from salad_core import limits

    path = Path(weights_dir) / VOCABULARY_FILE
    if not path.is_file():
        return None
    limits.check_inside(weights_dir, path, VOCABULARY_FILE, VOCABULARY_FILE, weights_dir, allow_outside_paths)
    try:    # size, UTF-8 and nesting checked before parsing (salad_core.limits)
        doc = limits.read_json(path, "vocabulary file", expect=None)
    except OSError as err:
        raise ValueError(f"{path} cannot be read ({err})") from err
    if not isinstance(doc, dict) or not isinstance(doc.get("words"), list):
        raise ValueError(f"{path} must hold a JSON object with a \"words\" list")
    return doc


def load_vocabulary(weights_dir: str | Path, allow_outside_paths: bool | str | Path = False
                    ) -> frozenset[str] | None:
    """The training vocabulary of a weights folder (its ``vocabulary.json``), or None if it has none
    (``allow_outside_paths``: see :func:`vocabulary_info`)."""
    doc = vocabulary_info(weights_dir, allow_outside_paths)
    return None if doc is None else frozenset(str(w) for w in doc["words"])


def vocabulary_and_source(weights_dir: str | Path, allow_outside_paths: bool | str | Path = False
                          ) -> tuple[frozenset[str] | None, str | None]:
    """``(words, source)`` of a weights folder for the pipelines: the vocabulary and the name of its
    corpus (e.g. "procedural corpus 2.4"); ``(None, None)`` without a file. An unreadable file, or one that
    links outside the folder (without ``allow_outside_paths``, :func:`vocabulary_info`), is logged with the
    reason and treated as absent (the weights still load; unknown words are not reported)."""
    try:
        doc = vocabulary_info(weights_dir, allow_outside_paths)
    except ValueError as err:
        logging.getLogger(__name__).warning("%s; unknown words will not be reported", err)
        return None, None
    if doc is None:
        return None, None
    version = doc.get("corpus_version")
    source = doc.get("source") or (f"{doc.get('corpus', 'procedural')} corpus {version}" if version else None)
    return frozenset(str(w) for w in doc["words"]), source


# ----------------------------------------------------------------------------------- checking
@dataclass
class PromptCheck:
    """What of a prompt a model can read.

    Attributes
    ----------
    prompt : str
    unknown : list of str
        Words (``split_words``) outside the vocabulary, in prompt order, each once.
    foreign : list of str
        Whitespace-separated pieces holding letters or symbols outside ASCII (another script, emoji,
        accented words): nothing in the training captions looks like them.
    unk_tokens : int or None
        How many tokens the encoder made ``[UNK]`` (None when not known).
    content : int
        Content terms: words outside :data:`FUNCTION_WORDS` plus foreign pieces.
    unknown_content : int
        Of those, how many are unknown.
    has_vocabulary : bool
        Whether ``unknown`` was checked against a vocabulary (else only foreign text is found).
    """

    prompt: str
    unknown: list[str] = field(default_factory=list)
    foreign: list[str] = field(default_factory=list)
    unk_tokens: int | None = None
    content: int = 0
    unknown_content: int = 0
    has_vocabulary: bool = True

    @property
    def terms(self) -> list[str]:
        """Everything unknown, in prompt order: unknown words and foreign pieces."""
        return _in_prompt_order(self.prompt, self.unknown + self.foreign)

    @property
    def mostly_unknown(self) -> bool:
        """More than half of the content terms unknown, or no known content term at all but something
        unreadable (``[UNK]`` tokens, foreign pieces)."""
        if self.content == 0:
            return bool(self.foreign or self.unk_tokens)
        return self.unknown_content / self.content > MOSTLY_UNKNOWN

    def __bool__(self) -> bool:
        return bool(self.unknown or self.foreign or self.unk_tokens)


def _is_foreign_char(ch: str) -> bool:
    """A character outside ASCII that is a letter, digit, mark or symbol (not punctuation/space)."""
    return ord(ch) > 127 and unicodedata.category(ch)[0] in "LNMS"


def _in_prompt_order(prompt: str, terms: Sequence[str]) -> list[str]:
    low = prompt.lower()
    return sorted(terms, key=lambda t: (low.find(t.lower()) if t.lower() in low else len(low)))


def check_prompt(prompt: str, vocabulary: Iterable[str] | None, tokens: Sequence[str] | None = None) -> PromptCheck:
    """Which words of ``prompt`` the model never saw.

    Parameters
    ----------
    prompt : str
    vocabulary : set of str or None
        Training vocabulary (:func:`load_vocabulary`); None checks only for foreign text and ``[UNK]``.
    tokens : list of str, optional
        The encoder's tokens of the prompt (``TextBatch.tokens[b]``), to count ``[UNK]`` tokens.

    Returns
    -------
    PromptCheck
    """
    vocab = None if vocabulary is None else (vocabulary if isinstance(vocabulary, (set, frozenset))
                                             else frozenset(vocabulary))
    foreign: list[str] = []
    foreign_spans: list[tuple[int, int]] = []
    for m in re.finditer(r"\S+", prompt):
        piece = m.group()
        if any(_is_foreign_char(ch) for ch in piece):
            core = piece.strip("".join(ch for ch in piece if unicodedata.category(ch)[0] == "P"))
            core = core or piece
            if core not in foreign:
                foreign.append(core)
            foreign_spans.append(m.span())
    unknown: list[str] = []
    content = unknown_content = 0
    seen: set[str] = set()
    low = prompt.lower()
    # words of foreign pieces ("café" -> "caf") are reported with their piece, not again as words
    for m in _WORD_RE.finditer(low):
        if any(s <= m.start() < e for s, e in foreign_spans):
            continue
        word = m.group()
        if word in seen:
            continue
        seen.add(word)
        known = vocab is None or word in vocab
        if word not in FUNCTION_WORDS:
            content += 1
            unknown_content += not known
        if not known:
            unknown.append(word)
    content += len(foreign)
    unknown_content += len(foreign)
    unk = None if tokens is None else sum(t in UNK_TOKENS for t in tokens)
    return PromptCheck(prompt, unknown, foreign, unk, content, unknown_content, vocab is not None)


def describe_unknown(check: PromptCheck, index: int | str | None = None, corpus: str | None = None) -> str:
    """One line about a :class:`PromptCheck` with something unknown ("" when everything is known).

    ``index``: the prompt's number in its batch (``"prompt 2 '...'"``), or a label (``"target 0"``).
    """
    if not check:
        return ""
    label = "prompt" if index is None else f"prompt {index}" if isinstance(index, int) else str(index)
    head = f"{label} {check.prompt!r}"
    parts = []
    where = f"the training captions ({corpus})" if corpus else "the training captions"
    if check.unknown:
        parts.append(f"{len(check.unknown)} word{'s' * (len(check.unknown) > 1)} never seen in {where}: "
                     + ", ".join(check.unknown))
    if check.foreign:
        parts.append("text the model cannot read (another script, emoji or accents; it learned English "
                     "captions only): " + ", ".join(check.foreign))
    if check.unk_tokens:
        parts.append(f"{check.unk_tokens} [UNK] token{'s' * (check.unk_tokens > 1)} (no meaning at all)")
    text = f"{head}: " + "; ".join(parts)
    if check.mostly_unknown:
        share = ("none of its content words known" if check.unknown_content >= check.content else
                 f"{check.unknown_content} of its {check.content} content words unknown")
        text += f"; the prompt is mostly unknown to the model ({share}), so the motion will not follow it"
    else:
        text += "; the motion will not follow these words"
    return text


def unknown_words_message(checks: Sequence[PromptCheck], corpus: str | None = None,
                          labels: Sequence[str] | None = None) -> str:
    """One warning text for every prompt of a call that has something unknown ("" if none has);
    ``labels`` name the prompts (default ``prompt b`` when there are several)."""
    if labels is None:
        labels = [f"prompt {b}" for b in range(len(checks))] if len(checks) > 1 else ["prompt"] * len(checks)
    lines = [describe_unknown(c, lab, corpus) for c, lab in zip(checks, labels)]
    return " | ".join(line for line in lines if line)


def _main(argv: Sequence[str] | None = None) -> int:
    import argparse

    p = argparse.ArgumentParser(prog="python -m salad_core.vocabulary",
                                description="write the training vocabulary of a corpus into a weights folder")
    p.add_argument("corpus", help="corpus folder (HumanML3D layout)")
    p.add_argument("--out", required=True, help="weights folder to write vocabulary.json into")
    p.add_argument("--split", default="train")
    p.add_argument("--corpus-version", default=None, help="generator version of the corpus, recorded")
    p.add_argument("--commit", default=None, help="commit the corpus was built at, recorded")
    args = p.parse_args(argv)
    root = Path(args.corpus)
    info: dict = {"corpus": "procedural", "corpus_version": args.corpus_version, "commit": args.commit,
                  "split": args.split}
    meta = root / "corpus.json"
    if meta.is_file():
        try:
            doc = json.loads(meta.read_text())
        except ValueError:
            doc = {}
        info["corpus_version"] = info["corpus_version"] or doc.get("version")
        info["size"], info["seed"] = doc.get("size"), doc.get("seed")
    at = f" (at commit {args.commit})" if args.commit else ""
    info["build"] = (f"python -m salad_core.cli corpus build --out DIR --size {info.get('size') or 'default'} "
                     f"--seed {info.get('seed', 0) if info.get('seed') is not None else 0}{at}; "
                     f"python -m salad_core.vocabulary DIR --out WEIGHTS_DIR")
    ids = (root / f"{args.split}.txt").read_text().split()
    info["n_clips"] = len(ids)
    info = {k: v for k, v in info.items() if v is not None}
    info["note"] = ("lower-case word forms (salad_core.data.texts.split_words) of the captions of the corpus split "
                    "these weights were trained on; salad_core.vocabulary.training_vocabulary rebuilds the list")
    words = training_vocabulary(root, args.split)
    path = write_vocabulary(words, args.out, **info)
    print(f"{path}: {len(words)} words from {len(ids)} clips")
    return 0


if __name__ == "__main__":  # pragma: no cover
    raise SystemExit(_main())
