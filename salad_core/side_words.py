"""Side words of a prompt: which words name the left or the right side, and the caption of a mirror image.

A motion's mirror image (:func:`salad_core.motion.mirror_features`) is described by its caption with every side
word swapped, as HumanML3D's ``M`` clips are: "left" <-> "right", "leftwards" <-> "rightwards", and the turning
senses seen from above ("clockwise" is a turn to the right). Used by KeyMotion's side-canonical PST
(:mod:`salad_core.keymotion.sides`) and by the mirroring of a take's limbs (:mod:`salad_core.attention.mirror_take`).
"""
from __future__ import annotations

import re

__all__ = ["MIRROR_SIDE_WORDS", "mirror_side_words", "names_left_first"]

#: Side words and their mirror images (lower case): left and right, and the turning senses seen from above
#: (clockwise is a turn to the right). Hyphenated forms ("counter-clockwise") are matched as one word.
MIRROR_SIDE_WORDS = {"left": "right", "right": "left", "leftward": "rightward", "rightward": "leftward",
                     "leftwards": "rightwards", "rightwards": "leftwards", "clockwise": "counterclockwise",
                     "counterclockwise": "clockwise", "anticlockwise": "clockwise",
                     "counter-clockwise": "clockwise", "anti-clockwise": "clockwise"}
#: Side words of the left kind (a turn counterclockwise seen from above is a turn to the left).
_LEFT_KIND = frozenset({"left", "leftward", "leftwards", "counterclockwise", "anticlockwise", "counter-clockwise",
                        "anti-clockwise"})
_SIDE_WORD = re.compile(r"[A-Za-z]+(?:-[A-Za-z]+)?")


def _side_words(text: str) -> list[tuple[int, int, str]]:
    """``(start, end, lower-case word)`` of the side words of ``text`` in order (a hyphenated side word such as
    "counter-clockwise" whole; in other hyphenated words, e.g. "left-handed", their side parts)."""
    out = []
    for m in _SIDE_WORD.finditer(text):
        w = m.group(0).lower()
        if w in MIRROR_SIDE_WORDS:
            out.append((m.start(), m.end(), w))
        elif "-" in w:
            for part in re.finditer(r"[A-Za-z]+", m.group(0)):
                if part.group(0).lower() in MIRROR_SIDE_WORDS:
                    out.append((m.start() + part.start(), m.start() + part.end(), part.group(0).lower()))
    return out


def _with_case(word: str, like: str) -> str:
    if like.isupper() and len(like) > 1:
        return word.upper()
    return word[0].upper() + word[1:] if like[:1].isupper() else word


def mirror_side_words(text: str) -> str:
    """The caption of the mirror image of a motion: ``text`` with every side word swapped
    (:data:`MIRROR_SIDE_WORDS`; case of the first letter kept), everything else unchanged.

    ``"Turns left, then kicks with the right foot"`` -> ``"Turns right, then kicks with the left foot"``.
    Mirroring twice gives the text back, except that "anticlockwise" and "counter-clockwise" come back as
    "counterclockwise".
    """
    if not isinstance(text, str):
        raise TypeError(f"text must be a str, got {type(text).__name__}")
    out, last = [], 0
    for start, end, w in _side_words(text):
        out.append(text[last: start])
        out.append(_with_case(MIRROR_SIDE_WORDS[w], text[start: end]))
        last = end
    out.append(text[last:])
    return "".join(out)


def names_left_first(text: str) -> bool:
    """True when the first side word of ``text`` is of the left kind ("left", "leftwards",
    "counterclockwise", ...): the prompts a side-canonical PST (``PSTConfig.side_canonical``) sees mirrored.
    Texts without side words give False."""
    if not isinstance(text, str):
        raise TypeError(f"text must be a str, got {type(text).__name__}")
    words = _side_words(text)
    return bool(words) and words[0][2] in _LEFT_KIND
