"""lab/scripts/editing/measure_new_edits.py and _measure_common.py: the edits beyond the paper and repetition
counting measured on the corpus's annotations (moved from tests/test_new_edits.py)."""
from __future__ import annotations

import numpy as np
import pytest

PIPE_SEED = 3  # seed of the tiny pipeline, conftest's `pipe` fixture (as in tests/test_new_edits.py)


def _bumps(k: int, n: int = 120, width: int = 10) -> np.ndarray:
    """``k`` raised-cosine bumps separated by rests, ``(n,)`` (as in tests/test_new_edits.py)."""
    x = np.zeros(n)
    centres = np.linspace(0, n, k + 2)[1:-1]
    t = np.arange(n)
    for c in centres:
        d = np.abs(t - c)
        x += np.where(d < width, 0.5 * (1 + np.cos(np.pi * d / width)), 0.0)
    return x


def test_measure_script_runs_on_a_tiny_pipeline(pipe, tmp_path):
    import json

    from _lab import load_script

    from salad_core.data.procedural import build_corpus

    script = load_script("measure_new_edits")
    assert script.stated_count("kicks with his left leg twice") == 2
    assert script.stated_count("does three squats") == 3 and script.stated_count("nods two times") == 2
    assert script.stated_count("waves his right hand") is None
    a = _bumps(1, 80, 8)
    assert script.activity_lag(a, np.roll(a, 12), (20, 60), 24) == 12
    build_corpus(tmp_path / "corpus", size=20, progress=False)
    pipe.save_pretrained(tmp_path / "weights")
    res = script.main(["--data", str(tmp_path / "corpus"), "--weights", str(tmp_path / "weights"), "--quick",
                       "--json", str(tmp_path / "out.json")])
    assert set(res) >= {"erase", "shift", "example", "counting"}
    assert res["example"]["items"] and res["example"]["summary"]["temporal (0, 0.5)"]["diversity_variations"] > 0
    assert {r["variant"] for r in res["shift"]["items"]} <= {"cross+temporal"}
    for row in res["shift"]["items"]:
        assert abs(row["shift"]) == 20 and row["error"] == abs(row["lag"] - row["shift"])
    saved = json.loads((tmp_path / "out.json").read_text())
    assert saved["settings"]["steps"] == 10


def test_measure_scripts_shared_helpers(tmp_path, capsys):
    """scripts/_measure_common: the annotated-clip walk both scripts read the corpus with, the mean
    that skips missing values, and the summary table format."""
    from _doubles import make_fake_corpus
    from _lab import load_script

    from salad_core.data.procedural import build_corpus

    common = load_script("_measure_common")
    root = tmp_path / "corpus"
    build_corpus(root, size=20, progress=False)
    listed = (root / "train.txt").read_text().split()
    walked = list(common.annotated_clips(root, "train", max_frames=64, min_frames=16))
    assert walked and [cid for cid, _, _ in walked] == [i for i in listed if i in {c for c, _, _ in walked}]
    for cid, doc, feats in walked:
        full = np.load(root / "new_joint_vecs" / f"{cid}.npy")
        assert feats.dtype == np.float32 and len(feats) % 4 == 0 and 16 <= len(feats) <= 64
        np.testing.assert_array_equal(feats, full[:len(feats)].astype(np.float32))
        assert doc["captions"] and len(feats) == min(len(full) - len(full) % 4, 64)
    originals = [cid for cid, _, _ in common.annotated_clips(root, "train", max_frames=64, min_frames=16,
                                                              mirrors=False)]
    assert originals == [cid for cid, _, _ in walked if not cid.startswith("M")] and len(originals) < len(walked)
    with pytest.raises(SystemExit, match="no annotated clips"):
        list(common.annotated_clips(make_fake_corpus(tmp_path / "fake"), "train", max_frames=64, min_frames=16))
    assert common.mean([1.0, None, float("nan"), np.float32(3.0), True]) == pytest.approx(5 / 3)
    assert np.isnan(common.mean([None, float("inf")]))
    common.print_summary("T", {"a": 0.123456, "setting": {"x": 1.23456, "y": 2.0}, "n": 3}, width=4, nested_digits=2)
    assert capsys.readouterr().out == "\n== T\n  a    0.1235\n  setting x=1.2  y=2\n  n    3\n"
