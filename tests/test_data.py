"""MotionTextDataset / MotionWindowDataset / collate on small fake corpora built from real features."""
from __future__ import annotations

import json
import logging
import shutil
from pathlib import Path

import numpy as np
import pytest
import torch
from torch.utils.data import DataLoader

from salad_core.data import (
    MotionTextDataset,
    MotionWindowDataset,
    check_annotation,
    collate_motion_text,
    load_annotation,
    load_mean_std,
    split_words,
)
from salad_core.skeleton import PART_NAMES, get_skeleton

SK = get_skeleton("humanml3d")
D = SK.feature_dim


def _line(caption: str, start: float = 0.0, end: float = 0.0) -> str:
    toks = " ".join(f"{w}/X" for w in split_words(caption))
    return f"{caption}#{toks}#{start}#{end}"


def _write_clip(root: Path, name: str, feats: np.ndarray, lines: list[str]) -> None:
    np.save(root / "new_joint_vecs" / f"{name}.npy", feats.astype(np.float32))
    (root / "texts" / f"{name}.txt").write_text("\n".join(lines) + "\n")


@pytest.fixture
def raw(sample_features) -> np.ndarray:
    return np.asarray(sample_features, dtype=np.float32)  # (170, 263)


@pytest.fixture
def corpus(tmp_path, raw, sample_dir) -> Path:
    """A: 170 frames, 2 whole captions; B: 50; C: 30 (too short); L: 210 (too long);
    E: 120 frames with one whole caption, a 60-frame sub-clip (1 s - 4 s) and a too-short sub-clip."""
    root = tmp_path / "corpus"
    (root / "new_joint_vecs").mkdir(parents=True)
    (root / "texts").mkdir()
    _write_clip(root, "A", raw, [_line("a person walks forward."), _line("someone strolls ahead")])
    _write_clip(root, "B", raw[:50], [_line("a man jumps")])
    _write_clip(root, "C", raw[:30], [_line("a short clip")])
    _write_clip(root, "L", np.concatenate([raw, raw[:40]]), [_line("a long clip")])
    _write_clip(root, "E", raw[10:130], [_line("a person waves"), _line("the person kicks", 1.0, 4.0),
                                         _line("a tiny part", 0.5, 1.0)])
    (root / "train.txt").write_text("A\nB\nC\nL\nE\n")
    (root / "val.txt").write_text("B\n")
    (root / "test.txt").write_text("A\n\n")
    shutil.copy(sample_dir / "Mean.npy", root / "Mean.npy")
    shutil.copy(sample_dir / "Std.npy", root / "Std.npy")
    return root


def _raw_of(root: Path, item: dict) -> np.ndarray:
    m = np.load(root / "new_joint_vecs" / f"{item['motion_id']}.npy")
    return m[item["offset"]: item["offset"] + item["length"]]


# ------------------------------------------------------------------------------- items
def test_items_lengths_padding_and_normalisation(corpus):
    mean, std = load_mean_std(corpus, SK)
    ds = MotionTextDataset(corpus, "train", seed=0)
    entry_len = dict(zip(ds.names, ds.lengths.tolist()))
    for epoch in range(4):
        ds.set_epoch(epoch)
        for i in range(len(ds)):
            it = ds[i]
            n, full = it["length"], entry_len[it["name"]]
            assert it["motion"].shape == (196, D) and it["motion"].dtype == np.float32
            assert n % 4 == 0 and n in (full // 4 * 4, full // 4 * 4 - 4)
            assert np.all(it["motion"][n:] == 0)
            np.testing.assert_allclose(it["motion"][:n], (_raw_of(corpus, it) - mean) / std, rtol=1e-5, atol=1e-5)
            # de-normalising gives back the raw features
            np.testing.assert_allclose(it["motion"][:n] * std + mean, _raw_of(corpus, it), atol=1e-4)


def test_filtering_subclips_and_skip_counts(corpus, caplog):
    with caplog.at_level(logging.INFO, logger="salad_core.data.dataset"):
        ds = MotionTextDataset(corpus, "train", seed=0)
    assert sorted(ds.names) == ["A", "B", "E", "E_sub1"]
    assert dict(ds.skipped) == {"too_short": 1, "too_long": 1, "subclip_too_short": 1}
    assert ds.num_clips == 3
    assert "too_long" in caplog.text and "4 items" in caplog.text
    sub = ds[ds.names.index("E_sub1")]
    # seconds * 20: frames 20..80 of E's file, and only its own caption
    assert sub["caption"] == "the person kicks" and sub["tokens"] == ["the/X", "person/X", "kicks/X"]
    assert 20 <= sub["offset"] and sub["offset"] + sub["length"] <= 80 and sub["length"] in (56, 60)
    whole = ds[ds.names.index("E")]
    assert whole["caption"] == "a person waves"  # the sub-clip captions are not whole-clip captions


def test_upper_length_bound_is_exclusive_200(tmp_path, raw, sample_dir):
    root = tmp_path / "c"
    (root / "new_joint_vecs").mkdir(parents=True)
    (root / "texts").mkdir()
    long = np.concatenate([raw, raw])
    _write_clip(root, "k199", long[:199], [_line("kept")])
    _write_clip(root, "d200", long[:200], [_line("dropped")])
    (root / "train.txt").write_text("k199\nd200\n")
    ds = MotionTextDataset(root, normalize=False, random_crop=False)
    assert ds.names == ["k199"] and ds[0]["length"] == 196 and ds.skipped["too_long"] == 1


def test_seeded_determinism_and_epochs(corpus):
    a = MotionTextDataset(corpus, "train", seed=7)
    b = MotionTextDataset(corpus, "train", seed=7)

    def snapshot(ds):
        return [(it["caption"], it["length"], it["offset"]) for it in (ds[i] for i in range(len(ds)))]

    first = snapshot(a)
    assert first == snapshot(b) == snapshot(a)
    seen = {tuple(first)}
    for e in range(1, 6):
        a.set_epoch(e)
        seen.add(tuple(snapshot(a)))
    assert len(seen) > 1  # epochs re-draw crops/captions
    a.set_epoch(0)
    assert snapshot(a) == first
    np.testing.assert_array_equal(a[0]["motion"], b[0]["motion"])


def test_double_crop_rate_and_caption_choice(corpus):
    ds = MotionTextDataset(corpus, "test", seed=3)  # only clip A: 170 frames -> 168 or 164
    lengths, captions = [], set()
    for e in range(600):
        ds.set_epoch(e)
        it = ds[0]
        lengths.append(it["length"])
        captions.add(it["caption"])
        assert 0 <= it["offset"] <= 170 - it["length"]
    lengths = np.array(lengths)
    assert set(lengths.tolist()) == {168, 164}
    assert abs((lengths == 164).mean() - 1 / 3) < 0.06
    assert captions == {"a person walks forward.", "someone strolls ahead"}


def test_eval_mode_is_deterministic_full_clip_first_caption(corpus):
    ds = MotionTextDataset(corpus, "train", random_crop=False)
    for i, name in enumerate(ds.names):
        it = ds[i]
        assert it["length"] == ds.lengths[i] // 4 * 4
        assert it["offset"] == (20 if name == "E_sub1" else 0)
    assert ds[ds.names.index("A")]["caption"] == "a person walks forward."


def test_normalize_false_and_explicit_stats(corpus, raw):
    ds = MotionTextDataset(corpus, "test", normalize=False, random_crop=False)
    np.testing.assert_array_equal(ds[0]["motion"][:168], raw[:168])
    mean = np.full(D, 1.0, np.float32)
    std = np.full(D, 2.0, np.float32)
    ds2 = MotionTextDataset(corpus, "test", mean=mean, std=std, random_crop=False)
    np.testing.assert_allclose(ds2[0]["motion"][:168], (raw[:168] - 1.0) / 2.0, atol=1e-6)
    with pytest.raises(ValueError, match="std"):
        MotionTextDataset(corpus, "test", mean=mean, std=None)
    with pytest.raises(ValueError, match=r"mean has shape \(5,\)"):
        MotionTextDataset(corpus, "test", mean=np.zeros(5), std=np.ones(5))


def test_load_mean_std(corpus, sample_dir):
    mean, std = load_mean_std(corpus, "humanml3d")
    assert mean.dtype == std.dtype == np.float32 and mean.shape == std.shape == (D,)
    np.testing.assert_array_equal(std, np.load(sample_dir / "Std.npy"))
    with pytest.raises(ValueError, match=r"expects \(251,\)"):
        load_mean_std(corpus, "kit")
    (corpus / "Std.npy").unlink()
    with pytest.raises(FileNotFoundError, match="Std.npy"):
        load_mean_std(corpus)


def test_kit_skeleton_width_and_min_length(tmp_path):
    kit = get_skeleton("kit")
    root = tmp_path / "kit"
    (root / "new_joint_vecs").mkdir(parents=True)
    (root / "texts").mkdir()
    rng = np.random.default_rng(0)
    _write_clip(root, "k1", rng.normal(size=(30, kit.feature_dim)), [_line("kit clip")])
    _write_clip(root, "k2", rng.normal(size=(20, kit.feature_dim)), [_line("too short for kit")])
    (root / "train.txt").write_text("k1\nk2\n")
    ds = MotionTextDataset(root, skeleton="kit", normalize=False, random_crop=False)
    assert ds.min_length == kit.min_length == 24
    assert ds.names == ["k1"] and ds[0]["motion"].shape == (196, 251) and ds[0]["length"] == 28


# ------------------------------------------------------------------------------ windows
def test_window_dataset_counts_and_contents(corpus, raw):
    mean, std = load_mean_std(corpus)
    ds = MotionWindowDataset(corpus, "train", window=64)
    # A 170, B 50 (short), C 30 (short), L 210, E 120: every start position of every long clip
    assert len(ds) == (170 - 63) + (210 - 63) + (120 - 63)
    assert ds.skipped["too_short"] == 2
    assert ds.locate(0) == ("A", 0) and ds.locate(106) == ("A", 106) and ds.locate(107) == ("L", 0)
    assert ds.locate(len(ds) - 1) == ("E", 120 - 64)
    for i in (0, 106, 107, len(ds) - 1, -1):
        name, start = ds.locate(i)
        m = np.load(corpus / "new_joint_vecs" / f"{name}.npy")[start:start + 64]
        out = ds[i]["motion"]
        assert out.shape == (64, D) and out.dtype == np.float32
        np.testing.assert_allclose(out, (m - mean) / std, rtol=1e-5, atol=1e-5)
    with pytest.raises(IndexError, match="out of range"):
        ds[len(ds)]
    batch = next(iter(DataLoader(ds, batch_size=5, shuffle=False)))
    assert batch["motion"].shape == (5, 64, D)
    with pytest.raises(ValueError, match="no clip of at least 500 frames"):
        MotionWindowDataset(corpus, "train", window=500)


# ------------------------------------------------------------------------------ collate
def test_collate_shapes_trim_and_mask(corpus):
    ds = MotionTextDataset(corpus, "train", seed=1)
    items = [ds[i] for i in range(len(ds))]
    batch = collate_motion_text(items)
    lmax = max(it["length"] for it in items)
    assert batch["motion"].shape == (len(items), lmax, D) and batch["motion"].dtype == torch.float32
    assert batch["length"].dtype == torch.long and batch["length"].tolist() == [it["length"] for it in items]
    assert batch["mask"].shape == (len(items), lmax)
    assert batch["mask"].sum(1).tolist() == batch["length"].tolist()
    assert batch["caption"] == [it["caption"] for it in items] and batch["name"] == ds.names
    assert torch.all(batch["motion"][~batch["mask"]] == 0)
    full = collate_motion_text(items, trim=False)
    assert full["motion"].shape == (len(items), 196, D)
    torch.testing.assert_close(full["motion"][:, :lmax], batch["motion"])
    loader = DataLoader(ds, batch_size=2, shuffle=False, collate_fn=collate_motion_text)
    b0 = next(iter(loader))
    assert b0["motion"].shape[0] == 2 and b0["motion"].shape[1] == int(b0["length"].max())
    with pytest.raises(ValueError, match="at least one item"):
        collate_motion_text([])
    with pytest.raises(ValueError, match="lacks 'motion' or 'length'"):
        collate_motion_text([{"motion": np.zeros((4, D))}])


# --------------------------------------------------------------------------- annotations
def _annotation(name, n, captions, phrases_per_caption):
    return {"name": name, "num_frames": n, "fps": 20,
            "captions": [{"caption": c, "phrases": p} for c, p in zip(captions, phrases_per_caption)]}


@pytest.fixture
def annotated(corpus) -> Path:
    (corpus / "annotations").mkdir()
    ann_a = _annotation("A", 170, ["a person walks forward.", "someone strolls ahead"], [
        [{"text": "a person walks forward", "words": [0, 4], "parts": ["left leg", "right leg"], "frames": [10, 150]}],
        [{"text": "someone strolls", "words": [0, 2], "parts": ["root"], "frames": [0, 170]}],
    ])
    ann_e = _annotation("E", 120, ["a person waves", "the person kicks", "a tiny part"], [
        [{"text": "waves", "words": [2, 3], "parts": ["right arm"], "frames": [0, 120]}],
        [{"text": "kicks", "words": [2, 3], "parts": ["right leg"], "frames": [30, 50]}],
        [],
    ])
    for name, ann in (("A", ann_a), ("E", ann_e)):
        (corpus / "annotations" / f"{name}.json").write_text(json.dumps(ann))
    return corpus


def test_annotations_follow_crops(annotated):
    assert load_annotation(annotated, "B") is None
    assert load_annotation(annotated, "A")["num_frames"] == 170
    ds = MotionTextDataset(annotated, "train", seed=0, with_annotations=True)
    for e in range(20):
        ds.set_epoch(e)
        for i in range(len(ds)):
            it = ds[i]
            ann = it["annotation"]
            if it["motion_id"] == "B":
                assert ann is None
                continue
            assert ann["caption"] == it["caption"] and ann["num_frames"] == it["length"]
            assert ann["offset"] == it["offset"]
            src = load_annotation(annotated, it["motion_id"])
            line = [c["caption"] for c in src["captions"]].index(it["caption"])
            for ph, ph0 in zip(ann["phrases"], src["captions"][line]["phrases"]):
                f0, f1 = ph0["frames"]
                want = [min(max(f0 - it["offset"], 0), it["length"]), min(max(f1 - it["offset"], 0), it["length"])]
                assert ph["frames"] == want and ph["words"] == ph0["words"] and ph["parts"] == ph0["parts"]
            if it["name"] == "E_sub1":  # kick at 30..50 of E; the sub-clip starts at 20
                assert ann["phrases"][0]["frames"] == [30 - it["offset"], 50 - it["offset"]]
    # the stored annotation is not modified by cropping
    assert load_annotation(annotated, "E")["captions"][1]["phrases"][0]["frames"] == [30, 50]
    assert "annotation" not in MotionTextDataset(annotated, "train")[0]


@pytest.mark.parametrize("mutate, message", [
    (lambda a: a["captions"].pop(), "2 annotated captions for 3 text lines"),
    (lambda a: a.update(num_frames=99), "num_frames is 99 but the motion has 120 rows"),
    (lambda a: a["captions"][0]["phrases"][0].update(parts=["tail"]), "parts"),
    (lambda a: a["captions"][0]["phrases"][0].update(words=[2, 9]), r"words \[2, 9\]"),
    (lambda a: a["captions"][1]["phrases"][0].update(frames=[30, 500]), r"frames \[30, 500\]"),
    (lambda a: a["captions"][1].update(caption="something else"), "differs from the text line"),
])
def test_bad_annotations_are_named(annotated, mutate, message):
    path = annotated / "annotations" / "E.json"
    ann = json.loads(path.read_text())
    mutate(ann)
    path.write_text(json.dumps(ann))
    with pytest.raises(ValueError, match=message) as err:
        MotionTextDataset(annotated, "train", with_annotations=True)
    assert "E.json" in str(err.value)


def test_check_annotation_accepts_valid_input():
    ann = _annotation("x", 10, ["a man runs"], [[{"text": "runs", "words": [2, 3], "parts": list(PART_NAMES[:2]),
                                                   "frames": [0, 10]}]])
    check_annotation(ann, ["a man runs"], 10)  # no error
    with pytest.raises(ValueError, match="here: num_frames"):
        check_annotation(ann, ["a man runs"], 11, "here")


def test_invalid_json_is_named(annotated):
    (annotated / "annotations" / "B.json").write_text("{not json")
    with pytest.raises(ValueError, match="B.json is not valid JSON"):
        load_annotation(annotated, "B")


# ---------------------------------------------------------------------------------- errors
def test_missing_root_and_split(tmp_path, corpus):
    with pytest.raises(FileNotFoundError, match="does not exist"):
        MotionTextDataset(tmp_path / "nowhere")
    with pytest.raises(FileNotFoundError) as err:
        MotionTextDataset(corpus, "train_val")
    msg = str(err.value)
    assert "'train_val.txt'" in msg and str(corpus / "train_val.txt") in msg and "test, train, val" in msg


def test_missing_motion_folder_and_file(corpus):
    (corpus / "train.txt").write_text("A\nZ9\n")
    with pytest.raises(FileNotFoundError, match=r"split id 'Z9' has no motion file: looked for .*Z9\.npy"):
        MotionTextDataset(corpus, "train")
    shutil.rmtree(corpus / "new_joint_vecs")
    with pytest.raises(FileNotFoundError, match="motion folder not found: looked for .*new_joint_vecs"):
        MotionTextDataset(corpus, "test")


def test_wrong_width_names_file_and_widths(corpus, raw):
    np.save(corpus / "new_joint_vecs" / "B.npy", raw[:50, :250])
    with pytest.raises(ValueError, match=r"B\.npy: expected width 263 .* found 250"):
        MotionTextDataset(corpus, "val")


def test_nonfinite_motion_raises_or_is_skipped(corpus, raw):
    bad = raw[:50].copy()
    bad[3, 7] = np.nan
    np.save(corpus / "new_joint_vecs" / "B.npy", bad)
    with pytest.raises(ValueError, match=r"B\.npy contains NaN or inf"):
        MotionTextDataset(corpus, "train")
    ds = MotionTextDataset(corpus, "train", nonfinite="skip")
    assert "B" not in ds.names and ds.skipped["nonfinite"] == 1
    with pytest.raises(ValueError, match=r"window.*B\.npy|B\.npy contains NaN"):
        MotionWindowDataset(corpus, "train")
    with pytest.raises(ValueError, match="nonfinite='maybe' must be one of"):
        MotionTextDataset(corpus, "train", nonfinite="maybe")


def test_malformed_text_line_names_file_and_line(corpus):
    (corpus / "texts" / "B.txt").write_text(_line("a man jumps") + "\nno separators here\n")
    with pytest.raises(ValueError, match=r"texts/B\.txt:2: expected 4 '#'-separated fields"):
        MotionTextDataset(corpus, "val")
    (corpus / "texts" / "B.txt").unlink()
    with pytest.raises(FileNotFoundError, match=r"no text file for id 'B'"):
        MotionTextDataset(corpus, "val")


def test_bad_arguments(corpus):
    with pytest.raises(ValueError, match="min_length=300 must not exceed max_length=196"):
        MotionTextDataset(corpus, min_length=300)
    with pytest.raises(ValueError, match="unit_length=0 must be a positive int"):
        MotionTextDataset(corpus, unit_length=0)
    with pytest.raises(ValueError, match="no usable items"):
        MotionTextDataset(corpus, "val", min_length=100)
    ds = MotionTextDataset(corpus, "val")
    with pytest.raises(IndexError, match="out of range"):
        ds[5]


def test_crops_enumerate_every_window_an_item_can_take(tmp_path):
    """``crops()`` lists each (motion_id, offset, length) once, every random item is among them, and
    ``crop_features`` gives the item's rows (a cache of per-window results relies on both)."""
    from _doubles import make_fake_corpus

    root = make_fake_corpus(tmp_path / "fake", n_train=5, n_val=2, lengths=(41, 90))
    ds = MotionTextDataset(root, "train", max_length=88, random_crop=True, seed=3)
    crops = ds.crops()
    assert len(crops) == len(set(crops))
    # F = L floored to 4 frames at L - F + 1 starts, F - 4 at L - F + 5 starts
    assert len(crops) == sum(2 * (n % 4) + 6 for n in ds.lengths)
    seen = set()
    for epoch in range(60):
        ds.set_epoch(epoch)
        for i in range(len(ds)):
            it = ds[i]
            key = (it["motion_id"], it["offset"], it["length"])
            assert key in crops
            seen.add(key)
            np.testing.assert_array_equal(ds.crop_features(*key), it["motion"][: it["length"]])
    assert len(seen) > 0.9 * len(crops)             # the enumeration is not wider than the crops drawn
    val = MotionTextDataset(root, "val", max_length=88, random_crop=False)
    assert val.crops() == [(it["motion_id"], 0, it["length"]) for it in (val[i] for i in range(len(val)))]
    with pytest.raises(ValueError, match="does not fit clip"):
        ds.crop_features(crops[0][0], 0, 500)
    with pytest.raises(KeyError, match="not a clip"):
        ds.crop_features("nope", 0, 4)
