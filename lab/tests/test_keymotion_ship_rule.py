"""lab/scripts/keymotion/keymotion_ship_rule.py: the ship rule read from evaluate_keymotion.sh's records. On the
recorded 10-seed benchmarks it reproduces the figures the rule was written against (0.2: flight -6.77, sliding 0.245,
checks 509/640, named-side 20/30, diversity 37.6 cm; v3-rest: flight -1.38, sliding 0.184, checks 563), and a
candidate whose jumps fly passes."""
from __future__ import annotations

import json
import shutil

import pytest

from _lab import RECORDS, load_script

sr = load_script("keymotion_ship_rule")
PHYSICS = RECORDS / "physics"


def results(tmp_path, physics: str | dict, t2m: str = "v3-pst.json"):
    out = tmp_path / "eval"
    (out / "physics10").mkdir(parents=True)
    (out / "t2m").mkdir()
    if isinstance(physics, dict):
        (out / "physics10" / "physics.json").write_text(json.dumps(physics))
    else:
        shutil.copy(PHYSICS / physics, out / "physics10" / "physics.json")
    shutil.copy(RECORDS / "keymotion" / "t2m_packaged_evaluator" / t2m, out / "t2m" / "results.json")
    shutil.copy(RECORDS / "keymotion" / "time_stretch_probe.json", out / "stretch.json")
    return out


def test_readings_reproduce_the_rules_reference_figures():
    base = sr.benchmark_readings(json.loads((PHYSICS / "keymotion-0.2_10-seeds.json").read_text()))
    assert base["flight_fit"] == pytest.approx(-6.77, abs=0.005)
    assert base["stance_sliding"] == pytest.approx(0.245, abs=0.0005)
    assert base["checks"] == (509, 640) and base["named_side"] == (20, 30)
    assert base["seed_diversity_cm"] == pytest.approx(37.6, abs=0.05)
    rest = sr.benchmark_readings(json.loads((PHYSICS / "keymotion-v3-rest_10-seeds.json").read_text()))
    assert rest["flight_fit"] == pytest.approx(-1.38, abs=0.005) and rest["checks"] == (563, 640)
    assert rest["stance_sliding"] == pytest.approx(0.184, abs=0.0005)


def test_v3_rest_is_kept_out_by_its_flight_and_a_flying_copy_passes(tmp_path, capsys):
    assert sr.main([str(results(tmp_path / "a", "keymotion-v3-rest_10-seeds.json"))]) == 1
    text = capsys.readouterr().out
    assert "FAIL  flight fit" in text and "PASS  stance sliding" in text and "verdict: keep 0.2 (5 of 6" in text
    assert "v3-rest    a person jumps" in text                  # the stretch ratios are printed beside
    flying = json.loads((PHYSICS / "keymotion-v3-rest_10-seeds.json").read_text())
    for p in flying["generators"]["KeyMotion"]["prompts"]:
        if p["text"] in sr.JUMP_PROMPTS:
            for r in p["reports"]:
                r["flight_segment_accels"] = [-9.5]
    assert sr.main([str(results(tmp_path / "b", flying))]) == 0
    assert "verdict: ship (6 of 6" in capsys.readouterr().out


def test_missing_or_short_records_are_named(tmp_path, capsys):
    out = results(tmp_path, "keymotion-v3-pst.json")                       # a 3-seed record
    assert sr.main([str(out)]) == 2 and "3 seeds per prompt" in capsys.readouterr().err
    shutil.copy(PHYSICS / "keymotion-v3-rest_10-seeds.json", out / "physics10" / "physics.json")
    (out / "t2m" / "results.json").unlink()
    assert sr.main([str(out)]) == 2 and "t2m/results.json" in capsys.readouterr().err
    assert sr.main([str(tmp_path / "none")]) == 2 and "physics10" in capsys.readouterr().err
