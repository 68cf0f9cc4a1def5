"""The HumanML3D ``texts/<id>.txt`` line format and the word convention shared by salad.

A line is ``<caption>#<word/POS word/POS ...>#<start_sec>#<end_sec>``; start = end = 0 (or NaN)
means the caption covers the whole clip.

*Words* (for annotations, re-weighting and attention labels) are always
``split_words(caption)``: the lower-cased alphabetic runs of the caption, in order. Word indices
in the procedural corpus's annotations index into that list.
"""
from __future__ import annotations

import math
import re
from dataclasses import dataclass

__all__ = ["split_words", "TextLine", "parse_text_line", "format_text_line"]

_WORD_RE = re.compile(r"[a-z]+")


def split_words(caption: str) -> list[str]:
    """Lower-cased alphabetic words of a caption: ``"A man, jumps!" -> ["a", "man", "jumps"]``."""
    return _WORD_RE.findall(caption.lower())


@dataclass(frozen=True)
class TextLine:
    caption: str
    tokens: tuple[str, ...]   # "word/POS" strings
    start: float              # seconds; 0 with end 0 means the whole clip
    end: float

    @property
    def whole_clip(self) -> bool:
        return self.start == 0.0 and self.end == 0.0


def _seconds(value: str, what: str, where: str) -> float:
    try:
        x = float(value)
    except ValueError:
        raise ValueError(f"{where}: {what} time {value!r} is not a number") from None
    return 0.0 if math.isnan(x) else x


def parse_text_line(line: str, where: str = "<text>") -> TextLine:
    """Parse one line; ``where`` (e.g. ``"texts/000001.txt:3"``) is named in errors."""
    parts = line.rstrip("\n").split("#")
    if len(parts) != 4:
        raise ValueError(f"{where}: expected 4 '#'-separated fields (caption#tokens#start#end), found {len(parts)}")
    caption, toks, start, end = parts
    if not caption.strip():
        raise ValueError(f"{where}: empty caption")
    tokens = tuple(t for t in toks.split(" ") if t)
    for t in tokens:
        if "/" not in t:
            raise ValueError(f"{where}: token {t!r} is not of the form word/POS")
    return TextLine(caption.strip(), tokens, _seconds(start, "start", where), _seconds(end, "end", where))


def format_text_line(caption: str, tagged: list[tuple[str, str]], start: float = 0.0, end: float = 0.0) -> str:
    """One ``texts`` line from a caption and its ``(word, POS)`` pairs (no trailing newline)."""
    if "#" in caption or "\n" in caption:
        raise ValueError(f"caption may not contain '#' or newlines: {caption!r}")
    toks = " ".join(f"{w}/{p}" for w, p in tagged)
    return f"{caption}#{toks}#{start}#{end}"
