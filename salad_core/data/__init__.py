"""Motion-text data: the HumanML3D directory layout, its text-line format, and loaders.

``salad_core.data.procedural`` generates a corpus in the same layout (the embedded default).
"""
from salad_core.data.dataset import (
    TEXT_FPS,
    MotionTextDataset,
    MotionWindowDataset,
    check_annotation,
    collate_motion_text,
    load_annotation,
    load_mean_std,
    read_split,
    read_texts,
)
from salad_core.data.texts import TextLine, format_text_line, parse_text_line, split_words

__all__ = [
    "TEXT_FPS",
    "MotionTextDataset",
    "MotionWindowDataset",
    "check_annotation",
    "collate_motion_text",
    "load_annotation",
    "load_mean_std",
    "read_split",
    "read_texts",
    "TextLine",
    "format_text_line",
    "parse_text_line",
    "split_words",
]
