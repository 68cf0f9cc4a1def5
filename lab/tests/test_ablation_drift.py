"""Stage drift of the staged ablation study: each row's change between stages against the pairs' paired gaps."""
import json

import numpy as np
import pytest

from salad_lab.drift import drift_markdown, load_group_evaluations, pair_gaps, row_drift


def _doc(steps: int, values: dict) -> dict:
    """An evaluation file of a denoiser group with Table 3's first pair and supplement Table 3's pair."""
    rows = {}
    for variant, per_metric in values.items():
        summary = {m: [float(np.mean(v)), float(1.96 * np.std(v) / np.sqrt(len(v)))] for m, v in per_metric.items()}
        rows[variant] = {"variant": variant, "steps": steps, "values": per_metric, "summary": summary}
    return {"steps": steps, "kind": "denoiser", "group": "denoisers", "rows": rows, "compare": "intervals",
            "tables": {"table3": {"full": "Full model", "no_st": "w/o ST-Latent"},
                       "supp_table3": {"full": "with FiLM", "no_film": "without FiLM"}}}


def _series():
    # full's FID jumps by +2.0 from the first to the second stage; its gap to no_st is 0.5 (smaller: within
    # drift) and to no_film 4.0 (larger than either row's change: not within drift)
    first = _doc(100, {"full": {"FID": [1.0, 2.0, 3.0], "R-precision top-3": [0.8, 0.8, 0.8]},
                       "no_st": {"FID": [1.5, 2.5, 3.5], "R-precision top-3": [0.7, 0.7, 0.7]},
                       "no_film": {"FID": [5.0, 6.0, 7.0], "R-precision top-3": [0.6, 0.6, 0.6]}})
    second = _doc(200, {"full": {"FID": [3.0, 4.0, 5.0], "R-precision top-3": [0.8, 0.8, 0.8]},
                        "no_st": {"FID": [2.5, 3.5, 4.5], "R-precision top-3": [0.7, 0.7, 0.7]},
                        "no_film": {"FID": [7.0, 8.0, 9.0], "R-precision top-3": [0.7, 0.7, 0.7]}})
    return [first, second]


def test_row_drift_is_each_rows_change_between_stages():
    drift = row_drift(_series(), "FID")
    assert drift["full"]["means"] == pytest.approx([2.0, 4.0])
    assert drift["full"]["last_change"] == pytest.approx(2.0)
    assert drift["no_st"]["last_change"] == pytest.approx(1.0)
    assert row_drift(_series(), "R-precision top-3")["no_film"]["last_change"] == pytest.approx(0.1)
    with pytest.raises(ValueError, match="Diversity"):
        row_drift(_series(), "Diversity")


def test_pair_gaps_compare_the_final_gap_with_the_rows_drift():
    gaps = {(p["b"], p["metric"]): p for p in pair_gaps(_series())}
    st = gaps[("no_st", "FID")]
    # at 100 steps full is 0.5 better (lower FID); at 200 it is 0.5 worse; full itself moved 2.0
    assert [g[0] for g in st["gaps"]] == pytest.approx([0.5, -0.5])
    assert st["drift_a"] == pytest.approx(2.0) and st["within_drift"]
    film = gaps[("no_film", "FID")]
    assert film["gaps"][-1][0] == pytest.approx(4.0) and not film["within_drift"]
    # R-precision: full 0.1 ahead of no_film at the end while no_film moved 0.1: not smaller, not within drift
    rp = gaps[("no_film", "R-precision top-3")]
    assert rp["gaps"][-1][0] == pytest.approx(0.1) and not rp["within_drift"]


def test_drift_markdown_reads_a_shipped_folder(tmp_path):
    (tmp_path / "evaluations").mkdir()
    for doc in _series():
        (tmp_path / "evaluations" / f"denoisers@{doc['steps']}.json").write_text(json.dumps(doc))
    text = drift_markdown(tmp_path)
    assert "| `full` | FID | 2.000 | 4.000 | +2.000 |" in text
    assert "| `full` vs `no_st` | FID | +0.500 ± 0.000 | -0.500 ± 0.000 | +2.000 / +1.000 | yes |" in text
    assert "| `full` vs `no_film` | FID | +4.000 ± 0.000 | +4.000 ± 0.000 | +2.000 / +2.000 | no |" in text
    with pytest.raises(FileNotFoundError, match="vaes"):
        load_group_evaluations(tmp_path, "vaes")
    (tmp_path / "evaluations" / "denoisers@200.json").unlink()
    with pytest.raises(ValueError, match="one evaluated stage"):
        drift_markdown(tmp_path)
