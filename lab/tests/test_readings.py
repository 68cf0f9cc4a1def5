"""The study's reading shipped beside the ablation models (salad_core/weights/ablations/readings.json) is what the
records give now, the toolkit reads it, and the report's tables print from the records alone."""
from __future__ import annotations

import json

from _lab import SHIPPED, load_script


def test_the_shipped_reading_is_up_to_date_with_the_records(capsys):
    assert load_script("write_readings").main(["--check"]) == 0, capsys.readouterr().out


def test_the_toolkit_reads_the_same_verdicts():
    from salad_core.ablation_models import load_readings

    from salad_lab.reading import pair_readings

    readings = load_readings()
    assert list(readings["tables"]) == ["table2", "supp_table4", "table3", "supp_table2", "supp_table3"]
    stage = json.loads((SHIPPED / "evaluations" / "vaes@6000.json").read_text())
    vaes = [p for p in readings["pairs"] if p["group"] == "vaes"]
    assert [p["verdict"] for p in vaes] == [r["verdict"] for r in pair_readings(stage)]
    assert all(f"**{p['verdict']}**" in readings["verdicts"][p["group"]] for p in readings["pairs"])


def test_the_report_tables_print_from_the_records(capsys):
    assert load_script("report_tables").main(["--sections", "vaes"]) == 0
    out = capsys.readouterr().out
    assert "**Table 2 at 6,000 steps, with the parameter-matched probe:**" in out and "pose_matched" in out
