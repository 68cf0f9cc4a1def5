"""Short captions of edits, as figures, GIFs and explorer pages label an edited motion.

:func:`edit_label` names each edit class briefly with its arguments: ``Mirror(legs)``, ``Reweight(high=-1)``,
``Swap(walks->jumps, 0.8)``, ``Inpaint(arms@20:60)``, ``MirrorTake(arms)``; several edits are joined by `` + ``.
"""
from __future__ import annotations

from typing import Callable

__all__ = ["edit_label"]


def _words_text(words) -> str:
    """An edit's words for its label: phrases as they are, ``(start, stop)`` word spans as ``words 2:4``."""
    items = (words,) if isinstance(words, str) else tuple(words)
    return ", ".join(w if isinstance(w, str) else f"words {w[0]}:{w[1]}" for w in items)


def _swapped_words(source: str | None, target: str | None) -> str:
    """``walks->jumps`` for every word position where the target's word differs from the source's."""
    from salad_core.data.texts import split_words

    pairs = zip(split_words(source or ""), split_words(target or ""))
    return ", ".join(f"{a}->{b}" for a, b in pairs if a != b)


def _added_words(source: str | None, target: str | None) -> str:
    """``+slowly +forward``: the target's words that the source does not have (a refinement's additions)."""
    from salad_core.data.texts import split_words

    have = set(split_words(source or ""))
    return " ".join(f"+{w}" for w in split_words(target or "") if w not in have)


def _inpaint_region(spec) -> str:
    """``arms@20:60``: an Inpaint's ``describe()`` with its parts named by their group when they are exactly one
    (``INPAINT_GROUPS``: legs, arms, upper, lower)."""
    from salad_core.attention import INPAINT_GROUPS

    text = spec.describe()
    if spec.parts is None:
        return text
    group = next((g for g, parts in INPAINT_GROUPS.items() if set(parts) == set(spec.parts)), None)
    _, at, span = text.partition("@")
    return text if group is None else group + at + span


def _window_note(spec) -> str:
    """``steps 0:0.5`` when an edit's step window is not its class's default, else ``""``."""
    field = getattr(type(spec), "__dataclass_fields__", {}).get("steps")
    if field is None or tuple(spec.steps) == tuple(field.default):
        return ""
    return f"steps {spec.steps[0]:g}:{spec.steps[1]:g}"


#: ``(short name, arguments)`` of each edit class for :func:`edit_label`, by class name: the edit object,
#: the source prompt and the target prompt in.
_LABEL_PARTS: dict[str, Callable] = {
    "WordSwap": lambda e, s, t: ("Swap", [_swapped_words(s, t), f"{e.tau:g}"]),
    "Refine": lambda e, s, t: ("Refine", [_added_words(s, t)]),
    "Reweight": lambda e, s, t: ("Reweight", [f"{_words_text(e.words)}={e.scale:g}"]),
    "Mirror": lambda e, s, t: ("Mirror", [e.parts]),
    "MirrorSelfAttention": lambda e, s, t: ("MirrorSelf", [e.parts]),
    "InjectSelfAttention": lambda e, s, t: ("InjectSelf", ["+".join(e.kinds)]),
    "Erase": lambda e, s, t: ("Erase", [_words_text(e.words), "" if e.mode == "special" else e.mode]),
    "Shift": lambda e, s, t: ("Shift", [_words_text(e.words), f"{e.frames:+d} frames"]),
    "ShiftTemporal": lambda e, s, t: ("ShiftTemporal", [", ".join(e.parts), f"{e.frames:+d} frames"]),
    "ExampleBased": lambda e, s, t: ("Example", [f"seed={e.seed}"]),
    "Inpaint": lambda e, s, t: ("Inpaint", [_inpaint_region(e)]),
    "MirrorTake": lambda e, s, t: ("MirrorTake", [e.parts]),
}


def edit_label(edits, source: str | None = None, target: str | None = None) -> str:
    """A short caption of edits, as figures and GIFs label the edited motion: ``Mirror(legs)``,
    ``Reweight(high=-1)``, ``Swap(walks->jumps, 0.8)``, ``Inpaint(arms@20:60)``, ``Erase(slowly)``,
    ``Shift(waving, +20 frames)``, ``Example(seed=7)``; several
    edits joined by `` + ``; a step window other than the class's default is added (``steps 0:0.5``).
    ``source`` and ``target`` are the prompts (a word swap names the words it swaps, a refinement the
    words it adds); with no edit: ``"edited"``."""
    labels = []
    for spec in (edits,) if not isinstance(edits, (list, tuple)) else edits:
        describe = _LABEL_PARTS.get(type(spec).__name__, lambda e, s, t: (type(e).__name__, []))
        name, parts = describe(spec, source, target)
        parts = [p for p in [*parts, _window_note(spec)] if p]
        labels.append(f"{name}({', '.join(parts)})" if parts else name)
    return " + ".join(labels) or "edited"
