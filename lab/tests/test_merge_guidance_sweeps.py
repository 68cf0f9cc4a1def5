"""lab/scripts/guidance/merge_guidance_sweeps.py: records of one protocol merge into one record whose choice is the rule's over
all rows (the shipped record split in two and merged back chooses as it did); records measured differently, or
repeating a candidate, are refused by name."""
from __future__ import annotations

import copy
import json
from pathlib import Path

import pytest

from _lab import load_script

from _lab import REPO, SHIPPED, STUDY, script_path  # noqa: E402
RECORD = REPO / "salad_core" / "weights" / "salad" / "guidance_sweep.json"


@pytest.fixture(scope="module")
def S():
    return load_script("merge_guidance_sweeps")


def _halves(cut: int = 3) -> tuple[dict, dict]:
    whole = json.loads(RECORD.read_text())
    a, b = copy.deepcopy(whole), copy.deepcopy(whole)
    a["rows"], b["rows"] = whole["rows"][:cut], whole["rows"][cut:]
    b["real"]["fid"]["mean"] *= 1 + 1e-7                      # another thread count's float rounding
    return a, b


def test_split_and_merged_back_chooses_as_the_whole_record(S, tmp_path, capsys):
    whole = json.loads(RECORD.read_text())
    a, b = _halves()
    (tmp_path / "a.json").write_text(json.dumps(a))
    (tmp_path / "b.json").write_text(json.dumps(b))
    assert S.main([str(tmp_path / "a.json"), str(tmp_path / "b.json"), "--out", str(tmp_path / "m")]) == 0
    merged = json.loads((tmp_path / "m" / "guidance_sweep.json").read_text())
    assert [r["label"] for r in merged["rows"]] == [r["label"] for r in whole["rows"]]
    assert merged["chosen"]["index"] == whole["chosen"]["index"]
    assert merged["chosen"]["guidance"] == whole["chosen"]["guidance"]
    assert [r["source"] for r in merged["rows"]] == [str(tmp_path / "a.json")] * 3 + [str(tmp_path / "b.json")] * 3
    assert merged["settings"]["merged_from"] == [str(tmp_path / "a.json"), str(tmp_path / "b.json")]
    out = capsys.readouterr().out
    assert "**(chosen)**" in out and "records no weights digest" in out
    assert (tmp_path / "m" / "guidance_sweep.md").read_text().count("| w=") == len(whole["rows"])


def test_a_better_candidate_in_the_second_record_is_chosen(S):
    a, b = _halves()
    better = copy.deepcopy(b["rows"][0])                      # w 4.5 with a lower FID, as another option
    better["guidance"] = dict(better["guidance"], rescale=0.7)
    better["label"] = "w=4.5 phi=0.7"
    better["t2m"]["fid"]["mean"] -= 0.01
    b["rows"].append(better)
    merged = S.merge_records([a, b], ["a", "b"])
    assert merged["rows"][merged["chosen"]["index"]]["label"] == "w=4.5 phi=0.7"


@pytest.mark.parametrize("spoil, message", [
    (lambda b: b["settings"].update(t2m="other protocol"), "other 't2m' settings"),
    (lambda b: b["settings"].update(data="/other/corpus"), "other 'data' settings"),
    (lambda b: b["real"]["r_precision_top3"].update(mean=0.5), "real-motion r_precision_top3"),
    (lambda b: b["rows"].append(copy.deepcopy(b["rows"][0])), "is in both b and b"),
])
def test_records_measured_differently_are_refused(S, spoil, message):
    a, b = _halves()
    spoil(b)
    with pytest.raises(ValueError, match=message):
        S.merge_records([a, b], ["a", "b"])


def test_weights_digests_must_agree_when_both_records_have_them(S):
    a, b = _halves()
    a["settings"]["identity"] = {"weights": "abc", "evaluator": "e"}
    b["settings"]["identity"] = {"weights": "abd", "evaluator": "e"}
    with pytest.raises(ValueError, match="measured other weights"):
        S.merge_records([a, b], ["a", "b"])
    b["settings"]["identity"]["weights"] = "abc"
    assert S.merge_records([a, b], ["a", "b"])["settings"]["merge_notes"] == []


def test_one_record_or_a_missing_file_is_an_error(S, tmp_path):
    with pytest.raises(ValueError, match="at least two"):
        S.merge_records([json.loads(RECORD.read_text())], ["a"])
    with pytest.raises(SystemExit, match="no such sweep record"):
        S.main([str(RECORD), str(tmp_path / "none.json"), "--out", str(tmp_path)])
