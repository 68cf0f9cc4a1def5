"""The row-by-row reading of the paper's denoiser ablations: paper ordering, ours at the stage and after the decay."""
from __future__ import annotations

import pytest

from salad_lab.orderings import paired_advantage
from salad_lab.reading import pair_readings, paired_ordering, reading_markdown, verdict


def _row(fid, top3):
    import numpy as np

    def summary(v):
        return [float(np.mean(v)), 1.96 * float(np.std(v)) / len(v) ** 0.5]

    return {"values": {"FID": fid, "R-precision top-3": top3},
            "summary": {"FID": summary(fid), "R-precision top-3": summary(top3)}}


def _stage():
    return {"stage": "denoisers@8", "kind": "denoiser", "steps": 8,
            "tables": {"table3": {"full": "Full model", "no_st": "w/o ST-Latent", "no_cross": "w/o CrossAttn"},
                       "supp_table3": {"full": "with FiLM", "no_film": "without FiLM"}},
            "rows": {"full": _row([3.0, 3.2, 3.1], [0.81, 0.82, 0.80]),
                     "no_st": _row([2.0, 2.2, 2.1], [0.80, 0.81, 0.80]),       # better FID: reversed at the stage
                     "no_cross": _row([4.0, 4.5, 4.2], [0.58, 0.60, 0.59]),
                     "no_film": _row([3.1, 3.4, 3.1], [0.80, 0.81, 0.79])}}


def test_orderings_and_verdicts():
    assert paired_ordering((0.5, 0.4)) == ">" and paired_ordering((-0.5, 0.4)) == "<"
    assert paired_ordering((0.3, 0.4)) == "="
    assert verdict(">", ">", ">") == "reproduced"
    assert verdict("=", "=", ">") == "reproduced"               # the paper has them level, so do our intervals
    assert verdict(">", "=", ">") == "reproduced, paired only"
    assert verdict(">", "=", "=") == "level"
    assert verdict(">", "<", "<") == "reversed" and verdict(">", "=", "<") == "reversed"
    assert verdict("=", "=", "<") == "reproduced"              # the paper's test is the rows' intervals
    assert verdict("=", ">", ">") == "ordered, the paper level"


def test_pair_readings_read_the_continued_rows_where_both_were_continued():
    stage = _stage()
    continued = {"steps": 10, "sampler": {}, "rows": {"full": _row([1.6, 1.7, 1.65], [0.85, 0.86, 0.85]),
                                                      "no_st": _row([1.7, 1.6, 1.7], [0.84, 0.85, 0.85])}}
    readings = {(r["pair"], r["metric"]): r for r in pair_readings(stage, continued)}
    assert set(readings) == {(("full", "no_st"), "FID"), (("full", "no_st"), "R-precision top-3"),
                             (("full", "no_cross"), "FID"), (("full", "no_cross"), "R-precision top-3"),
                             (("full", "no_film"), "FID"), (("full", "no_film"), "R-precision top-3")}
    st = readings[(("full", "no_st"), "FID")]
    assert st["paper_order"] == ">" and st["stage"]["intervals"] == "<" and st["read_at"] == 10
    assert st["stage"]["advantage"] == pytest.approx(paired_advantage([3.0, 3.2, 3.1], [2.0, 2.2, 2.1], "FID"))
    assert st["continued"]["advantage"] == pytest.approx(paired_advantage([1.6, 1.7, 1.65], [1.7, 1.6, 1.7], "FID"))
    assert st["verdict"] == "level"                            # reversed at the stage, level after the decay
    cross = readings[(("full", "no_cross"), "R-precision top-3")]
    assert cross["continued"] is None and cross["read_at"] == 8 and cross["verdict"] == "reproduced"
    assert pair_readings(stage)[0]["verdict"] == "reversed"   # without the continuation: the stage's reading


def test_reading_markdown_has_a_row_per_pair_and_metric_with_its_note():
    text = reading_markdown(_stage(), None, notes={"full vs no_st, FID": "the seed moves it"}).splitlines()
    assert text[0] == "| table | pair | metric | paper | ours at 8 | verdict | what was measured |"
    assert len(text) == 2 + 6
    row = next(line for line in text if "w/o ST-Latent | FID" in line)
    assert "0.076 vs 0.433 (ahead)" in row and "**reversed** (at 8)" in row and row.endswith("the seed moves it |")
    with_decay = reading_markdown(_stage(), {"steps": 10, "rows": {}}).splitlines()
    assert "| ours after the decay (10) |" in with_decay[0] and "not continued" in with_decay[2]


def test_reading_refuses_other_stages_and_samplers():
    with pytest.raises(ValueError, match="reads VAE and denoiser stages"):
        pair_readings({**_stage(), "kind": "keymotion"})
    with pytest.raises(ValueError, match="guidance_scale"):
        pair_readings(_stage(), {"steps": 10, "sampler": {"guidance_scale": 4.5}, "rows": {}})
    with pytest.raises(ValueError, match="continued denoisers@6, not denoisers@8"):
        pair_readings(_stage(), {"stage": "denoisers@6", "steps": 10, "rows": {}})


def test_vae_stages_are_read_on_fid_and_mpjpe_in_cm():
    stage = {"stage": "vaes@6", "kind": "vae", "steps": 6,
             "tables": {"supp_table4": {"st": "Full model", "no_pos": "without L_pos"}},
             "rows": {"st": {"values": {"FID": [0.018, 0.019], "MPJPE": [0.0388, 0.0390]},
                             "summary": {"FID": [0.0185, 0.001], "MPJPE": [0.0389, 0.0002]}},
                      "no_pos": {"values": {"FID": [0.030, 0.031], "MPJPE": [0.0420, 0.0425]},
                                 "summary": {"FID": [0.0305, 0.001], "MPJPE": [0.04222, 0.0005]}}}}
    readings = pair_readings(stage)
    assert [r["metric"] for r in readings] == ["FID", "MPJPE"] and all(r["verdict"] == "reproduced" for r in readings)
    row = reading_markdown(stage).splitlines()[3]
    assert "| MPJPE (cm) | 1.60 vs 2.30 (ahead) | 3.89 ± 0.02 vs 4.22 ± 0.05; paired +0.34 ± " in row
