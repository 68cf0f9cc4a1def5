"""The field's physical measures on synthetic motions with known answers and on real capture:
GMD's skating ratio, PhysDiff's joint-based Penetrate / Float / Skate, contact from a robust level, stance
sliding apart from low swings, floating during stance, per-segment flight fits, p99s, the shown-vs-raw
deviation, the real-capture row and the benchmark's per-prompt breakdown."""
from __future__ import annotations

import math

import numpy as np
import pytest

from _doubles import rest_pose
from salad_core.data import deepmimic
from salad_core.eval import physics as ph
from salad_core.eval import physics_prompts as pp
from salad_core.skeleton import get_skeleton

SK = get_skeleton("humanml3d")
FPS = SK.fps
J = {n: i for i, n in enumerate(SK.joint_names)}
LEFT_FOOT = [J["left_ankle"], J["left_foot"]]
needs_pybullet = pytest.mark.skipif(not deepmimic.pybullet_available(),
                                    reason="pybullet (the optional extra 'deepmimic') is not installed")


def still(n: int = 40) -> np.ndarray:
    """The rest pose standing: left ankle and toe at y = 0, right ones at 1.02 cm."""
    return np.repeat(rest_pose()[None], n, axis=0)


def sliding(speed: float, n: int = 60, axis: int = 2) -> np.ndarray:
    """The rest pose translated along ``axis`` at ``speed`` m/s, feet on the floor."""
    d = np.zeros(3)
    d[axis] = 1.0
    return still(n) + (np.arange(n) / FPS * speed)[:, None, None] * d


# ------------------------------------------------------------------------------------ GMD
def test_gmd_ratio_counts_skids_with_gmds_moving_average():
    # 1 m/s: every pair skids, even the first and last, whose zero-padded 5-frame average is 3/5 m/s
    assert ph.gmd_skating_ratio(sliding(1.0)) == 1.0
    # 0.7 m/s: the end pairs' averages are 3/5 * 0.7 = 0.42 m/s < 0.5, so 57 of the 59 pairs skid
    assert ph.gmd_skating_ratio(sliding(0.7)) == pytest.approx(57 / 59)
    assert ph.gmd_skating_ratio(sliding(0.45)) == 0.0                 # below 0.5 m/s (2.5 cm per frame)
    # "either foot": lifted 4.5 cm only the left toe (0 -> 4.5 cm) stays under 5 cm, and it skids
    assert ph.gmd_skating_ratio(sliding(1.0) + [0, 0.045, 0]) == 1.0
    assert ph.gmd_skating_ratio(sliding(1.0) + [0, 0.06, 0]) == 0.0  # both toes above 5 cm: not in contact
    assert ph.measure_motion(sliding(0.7)).gmd_skate_ratio == pytest.approx(57 / 59)


# ------------------------------------------------------------------------------------ PhysDiff, joint-based
def test_physdiff_penetrate_float_skate_on_joints():
    assert ph.physdiff_measures(still()) == {"penetrate": 0.0, "float": 0.0, "skate": 0.0, "err": 0.0}
    hover = ph.physdiff_measures(still() + [0, 0.02, 0])
    assert hover == pytest.approx({"penetrate": 0.0, "float": 20.0, "skate": 0.0, "err": 20.0})
    sunk = ph.physdiff_measures(still() - [0, 0.03, 0])            # toes in contact (below the floor), not moving
    assert sunk == pytest.approx({"penetrate": 30.0, "float": 0.0, "skate": 0.0, "err": 30.0})
    # sliding at 0.5 m/s: only the left toe (y = 0) is within 5 mm of the floor; 2.5 cm per frame pair
    slide = ph.physdiff_measures(sliding(0.5))
    assert slide == pytest.approx({"penetrate": 0.0, "float": 0.0, "skate": 25.0, "err": 25.0})
    # within the 5 mm tolerance nothing counts
    assert ph.physdiff_measures(still() + [0, 0.004, 0])["float"] == 0.0
    rep = ph.measure_motion(still() - [0, 0.03, 0])
    assert rep.physdiff_penetrate_mm == pytest.approx(30.0) and rep.physdiff_err_mm == pytest.approx(30.0)


# ------------------------------------------------------------------------------------ contact level
def test_one_penetrating_frame_keeps_the_stance_contacts():
    x = still(40)
    x[20, J["left_foot"], 1] = -0.10                                # one frame, the toe 10 cm into the floor
    old = ph.PhysicsConfig(contact_reference="clip_min")
    # the old level (the single lowest foot point) lifts every other frame 10 cm off the "ground"
    assert ph.measure_motion(x, config=old).flight_frames == 39
    assert ph.contact_level(x) == pytest.approx(-0.10)              # the old one-argument form is unchanged
    rep = ph.measure_motion(x)                                      # default: 5th percentile of the lowest foot
    assert rep.contact_level_m == 0.0
    assert rep.flight_frames == 0 and rep.contact_count > 150
    assert rep.stance_count > 100 and rep.stance_slide_mean_ms == 0.0
    assert rep.penetration_max_cm == pytest.approx(10.0)
    # p99 over 40 frames interpolates towards the one deep frame: 0.61 of the way (numpy's linear rule)
    assert rep.penetration_p99_cm == pytest.approx(0.61 * 10.0)
    long = still(200)
    long[100, J["left_foot"], 1] = -0.10
    r200 = ph.measure_motion(long)
    assert r200.penetration_p99_cm == 0.0 and r200.penetration_max_cm == pytest.approx(10.0)


def test_contact_reference_floor_and_floating_during_stance():
    hover = still(30) + [0, 0.10, 0]                                # 10 cm over the floor, standing still
    floor = ph.PhysicsConfig(contact_reference="floor")
    assert ph.measure_motion(hover, config=floor).flight_frames == 30
    rep = ph.measure_motion(hover)                                  # the clip's own level: still in stance
    assert rep.flight_frames == 0 and rep.contact_level_m == pytest.approx(0.10)
    # floating during stance: the lower of ankle / toe of each foot above y = 0: 10 and 11.02 cm
    assert rep.stance_float_cm == pytest.approx((10.0 + 11.022) / 2)
    assert rep.stance_foot_frames == 2 * 30
    assert ph.measure_motion(still(30)).stance_float_cm == pytest.approx(1.022 / 2)
    with pytest.raises(ValueError, match="contact_reference"):
        ph.PhysicsConfig(contact_reference="lowest")


# ------------------------------------------------------------------------------------ stance vs low swings
def test_stance_sliding_of_a_foot_sliding_at_a_known_speed():
    rep = ph.measure_motion(sliding(0.3))
    assert rep.stance_slide_mean_ms == pytest.approx(0.3) and rep.stance_slide_p95_ms == pytest.approx(0.3)
    assert rep.stance_count == 4 * 59 and rep.low_swing_count == 0 and math.isnan(rep.low_swing_mean_ms)
    assert rep.gmd_skate_ratio == 0.0                               # 0.3 m/s is under GMD's 0.5 m/s


def bobbing_left_foot(n: int = 60, speed: float = 1.0, pattern=(0.0, 0.02)) -> np.ndarray:
    """The right foot planted; the left foot moves forward at ``speed`` m/s with its height cycling
    through ``pattern`` (m), low enough to count as contact by height."""
    x = still(n)
    x[:, LEFT_FOOT, 2] += (np.arange(n) / FPS * speed)[:, None]
    x[:, LEFT_FOOT, 1] += np.resize(np.asarray(pattern), n)[:, None]
    return x


def test_low_swings_are_reported_apart_from_stance_sliding():
    x = bobbing_left_foot()                                         # up and down 2 cm every frame: 0.4 m/s
    rep = ph.measure_motion(x)
    assert rep.stance_slide_mean_ms == pytest.approx(0.0) and rep.stance_count == 2 * 59   # the right foot
    assert rep.low_swing_mean_ms == pytest.approx(1.0) and rep.low_swing_count == 2 * 59   # the left foot
    assert rep.skate_mean_ms == pytest.approx(0.5)                  # the old measure mixes the two


def test_stance_needs_a_run_of_still_frames():
    # the left foot still over single frame pairs only (0, 0, 2, 2, 0, 0, ... cm): no run of 3 still frames
    x = bobbing_left_foot(pattern=(0.0, 0.0, 0.02, 0.02))
    st = ph.stance_analysis(x)
    assert not st["stance"][:, :2].any() and st["low_swing"][:, :2].all()
    two = ph.stance_analysis(x, config=ph.PhysicsConfig(stance_min_frames=2))
    assert two["stance"][:, :2].sum() == 2 * 30                     # every still pair once runs of 2 frames count
    assert two["speed"][:, 0][two["stance"][:, 0]] == pytest.approx(1.0)


# ------------------------------------------------------------------------------------ flight fits
def jump(g: float = 9.81, v0: float = 3.0, pre: int = 10, post: int = 10) -> tuple[np.ndarray, np.ndarray]:
    t = np.arange(int(2 * v0 / g * FPS) + 1) / FPS
    offs = np.concatenate([np.zeros(pre), np.maximum(v0 * t - 0.5 * g * t ** 2, 0.0), np.zeros(post)])
    return still(len(offs)) + offs[:, None, None] * np.array([0, 1.0, 0]), offs


def test_a_parabola_of_minus_9_81_fits_minus_9_81_per_segment():
    x, _ = jump(9.81)
    fits = ph.flight_fit_accelerations(x)
    assert fits.shape == (1,) and fits[0] == pytest.approx(-9.81, abs=1e-9)
    two = np.concatenate([x, jump(9.81, v0=2.0)[0]])
    rep = ph.measure_motion(two)
    assert rep.flight_segments == 2 and rep.flight_segment_accels == pytest.approx((-9.81, -9.81), abs=1e-9)
    assert rep.flight_fit_accel_ms2 == pytest.approx(-9.81, abs=1e-9)


def test_the_segment_median_is_not_dominated_by_one_wild_segment():
    a, _ = jump(9.81)
    b, _ = jump(9.81, v0=2.5)
    wild = still(40)
    wild[10:30, :, 1] += (0.3 + 10.0 * (np.arange(20) / FPS) ** 2)[:, None]  # 20 frames "flying" up at +20 m/s^2
    x = np.concatenate([a, b, wild])
    rep = ph.measure_motion(x)
    assert rep.flight_segments == 3
    assert rep.flight_segment_accels == pytest.approx((-9.81, -9.81, 20.0), abs=1e-9)
    assert rep.flight_fit_accel_ms2 == pytest.approx(-9.81, abs=1e-9)          # the median of 3 segments
    assert rep.flight_accel_ms2 > 0                                            # the pooled mean is pulled over 0
    # over motions: the median over every segment of every motion
    agg = ph.aggregate_reports([ph.measure_motion(a), ph.measure_motion(wild), ph.measure_motion(b)])
    assert agg["flight_segments"] == 3 and agg["flight_fit_accel_ms2"] == pytest.approx(-9.81, abs=1e-9)
    assert "flight_segment_accels" not in agg


def test_aggregate_reads_reports_saved_before_the_new_fields():
    old = {k: v for k, v in ph.measure_motion(still()).as_dict().items() if k in ph.AGGREGATION and
           k not in ("stance_slide_mean_ms", "stance_count", "flight_segment_accels", "gmd_skate_ratio")}
    agg = ph.aggregate_reports([old, ph.measure_motion(sliding(0.3))])
    assert agg["stance_slide_mean_ms"] == pytest.approx(0.3) and agg["gmd_skate_ratio"] == 0.0


# ------------------------------------------------------------------------------------ p99 of bones
def test_bone_p99_ignores_one_wild_frame_the_max_does_not():
    x = still(200)
    fore = x[:, J["left_wrist"]] - x[:, J["left_elbow"]]
    x[7, J["left_wrist"]] += 0.10 * fore[7] / np.linalg.norm(fore[7])     # one frame: forearm +10 cm
    rep = ph.measure_motion(x)
    assert rep.bone_ref_max_cm == pytest.approx(10.0) and rep.bone_ref_p99_cm == pytest.approx(0.0, abs=1e-9)
    assert ph.pooled_bone_percentile([x, still(10)], 99) == pytest.approx(0.0, abs=1e-9)
    assert ph.pooled_bone_percentile([x], 100) == pytest.approx(10.0)
    assert ph.pooled_penetration_percentile([still(10) - [0, 0.02, 0]], 99) == pytest.approx(2.0)


# ------------------------------------------------------------------------------------ shown vs raw
def test_recovery_deviation_of_identical_and_offset_motions():
    x = sliding(1.0)
    same = ph.recovery_deviation(x, x)
    assert same["p95_cm"] == same["p99_cm"] == same["max_cm"] == 0.0 and max(same["per_joint_max_cm"]) == 0.0
    assert same["travel_ratio"] == pytest.approx(1.0) and same["frames"] == 60
    off = ph.recovery_deviation(x + [0.03, 0.04, 0.0], x)               # 5 cm everywhere
    assert off["p95_cm"] == pytest.approx(5.0) and off["p99_cm"] == pytest.approx(5.0)
    assert off["max_cm"] == pytest.approx(5.0) and off["per_joint_p95_cm"] == pytest.approx([5.0] * 22)
    assert off["travel_ratio"] == pytest.approx(1.0)                    # a constant offset travels as far
    one = x.copy()
    one[:, J["left_wrist"]] += [0.0, 0.0, 0.08]
    dev = ph.recovery_deviation(one, x)
    assert dev["worst_joint"] == "left_wrist" and dev["per_joint_max_cm"][J["left_wrist"]] == pytest.approx(8.0)
    assert dev["per_joint_p95_cm"][J["head"]] == 0.0 and dev["max_cm"] == pytest.approx(8.0)
    assert dev["p95_cm"] == pytest.approx(0.0)                          # 1 joint of 22 is under 5 %
    # travel: the shown pelvis goes half as far as the raw one
    assert ph.travel_ratio(sliding(0.5), sliding(1.0)) == pytest.approx(0.5)
    assert math.isnan(ph.recovery_deviation(still(), still())["travel_ratio"])
    # pooled over motions
    pooled = ph.recovery_deviation([x, x + [0.0, 0.02, 0.0]], [x, x])
    assert pooled["frames"] == 120 and pooled["max_cm"] == pytest.approx(2.0)
    assert pooled["p95_cm"] == pytest.approx(2.0) and pooled["mean_cm"] == pytest.approx(1.0)
    with pytest.raises(ValueError, match="same motions"):
        ph.recovery_deviation(x, x[:-1])


# ------------------------------------------------------------------------------------ real capture
def test_the_real_sample_row_is_finite_and_plausible():
    x = pp.humanml3d_reference_joints()
    assert x.shape == (170, 22, 3) and x[..., 1].min() == 0.0
    row = pp.real_capture_row(deepmimic=False)
    assert row["name"] == "real capture (HumanML3D 012314 only)" and "alone" in row["note"]
    a = row["aggregate"]
    assert a["motions"] == 1 and list(row["clips"]) == ["HumanML3D 012314"]
    assert a["bone_ref_p99_pooled_cm"] < 0.01                          # HumanML3D's retargeted bones
    assert a["penetration_p99_pooled_cm"] == 0.0 and a["physdiff_penetrate_mm"] == 0.0
    assert 0.0 < a["stance_slide_mean_ms"] < 0.3 and a["stance_count"] > 100
    assert a["stance_slide_mean_ms"] < a["low_swing_mean_ms"]          # low swings move faster than stance
    assert 0.0 < a["gmd_skate_ratio"] < 0.3
    assert 0.0 < a["stance_float_cm"] < 3.0                            # a standing toe joint is ~1-2 cm up
    assert a["contact_level_m"] < 0.01


def test_without_pybullet_the_row_is_the_sample_alone_and_says_so(monkeypatch):
    monkeypatch.setattr(deepmimic, "pybullet_available", lambda: False)
    row = pp.real_capture_row()
    assert row["name"] == "real capture (HumanML3D 012314 only)"
    assert "pybullet" in row["note"] and "not installed" in row["note"]


@needs_pybullet
def test_the_deepmimic_clips_join_the_real_capture_row():
    row = pp.real_capture_row(deepmimic=True)
    n = len(pp.REAL_CAPTURE_DEEPMIMIC)
    assert row["name"] == f"real capture (HumanML3D 012314 + {n} DeepMimic clips)"
    assert len(row["clips"]) == n + 1 and row["aggregate"]["motions"] == n + 1
    walk = row["clips"]["DeepMimic walk"]
    assert walk["frames"] >= 40 and walk["stride_m"] > 0.4            # looped to HumanML3D's 40 frames; it steps
    a = row["aggregate"]
    for key in ("stance_slide_mean_ms", "gmd_skate_ratio", "stance_float_cm", "physdiff_err_mm",
                "flight_fit_accel_ms2", "bone_ref_p99_pooled_cm"):
        assert math.isfinite(a[key]), key
    assert a["bone_ref_p99_pooled_cm"] < 0.01                          # retargeted to HumanML3D's bones
    assert a["flight_segments"] >= 1                                   # the jumps and the run fly


# ------------------------------------------------------------------------------------ the benchmark
def test_benchmark_reports_deviation_per_prompt_and_issue_64_targets(tiny_procedural_corpus):
    walk = sliding(1.5, 120)

    def fitted(texts, lengths, seed):                                  # shown 2 cm above the raw read
        return pp.Generated([walk + [0, 0.02, 0] for _ in texts], [walk for _ in texts])

    def raw_only(texts, lengths, seed):
        return [walk for _ in texts]

    sink: dict = {}
    res = pp.run_benchmark({"fitted": fitted, "raw": raw_only}, pp.BenchSettings(steps=1, seeds=(0, 1)),
                           data_root=tiny_procedural_corpus, prompts=pp.PROMPTS[:2], deepmimic=False,
                           motions_sink=sink)
    f, r = res["generators"]["fitted"], res["generators"]["raw"]
    assert f["deviation"]["p95_cm"] == pytest.approx(2.0) and f["deviation"]["travel_ratio"] == pytest.approx(1.0)
    assert r["deviation"] is None and r["prompts"][0]["deviations"] is None
    summary = f["prompts"][0]["summary"]
    assert summary["deviation_p95_cm"] == pytest.approx(2.0) and summary["stance_slide_mean_ms"] == pytest.approx(1.5)
    assert summary["gmd_skate_ratio"] == 1.0 and "deviation_p95_cm" not in r["prompts"][0]["summary"]
    assert f["aggregate"]["bone_ref_p99_pooled_cm"] == pytest.approx(0.0, abs=1e-9)
    assert f["aggregate"]["penetration_p99_pooled_cm"] == 0.0
    real = res["references"][res["real_capture"]["name"]]
    rows = {t["target"].split(" (")[0].split(":")[0]: t["cells"] for t in pp.targets(res)}
    slide = rows["[field] stance sliding on the forward walks and runs <= 1.5x the real capture's"]
    assert slide["fitted"] == (pytest.approx(1.5), 1.5 <= 1.5 * real["stance_slide_mean_ms"])
    assert rows["[field] shown vs raw"]["fitted"][1] is True and rows["[field] shown vs raw"]["raw"] == (None, None)
    assert rows["[field] bones exact"]["fitted"][1] is True
    assert rows["[field] nothing below the floor"]["raw"][1] is True
    assert rows["[field] travel within 20 % of raw"]["fitted"] == (pytest.approx(1.0), True)
    assert rows["[field] floating during stance <= 2 cm"]["fitted"][1] is False   # 2 cm higher: 2.5 cm
    # the guidance sweep counts the issue-20 targets by prefix: the new ones must not match them
    from salad_core.eval.guidance_sweep import PHYSICS_TARGETS

    assert not [t for t in pp.targets(res) if t["target"].startswith("[field]")
                and any(t["target"].startswith(k) for k in PHYSICS_TARGETS)]
    md = pp.benchmark_markdown(res)
    assert "## The field's measures" in md and "## Shown vs raw" in md and "### fitted" in md
    assert "| fitted | 2.00 | 2.00 | 2.00 |" in md and "(no raw joints)" in md
    assert "| real capture (HumanML3D 012314 only) |" in md
    # the saved shown and raw joints replay the same figures
    assert sorted(k for k in sink if k.startswith("fitted/00/")) == ["fitted/00/0", "fitted/00/0/raw", "fitted/00/1",
                                                                       "fitted/00/1/raw"]
    again = pp.run_benchmark(pp.saved_generators(sink), pp.BenchSettings(steps=1, seeds=(0, 1)),
                             data_root=tiny_procedural_corpus, prompts=pp.PROMPTS[:2], deepmimic=False)
    for key in ("p95_cm", "p99_cm", "max_cm", "travel_ratio"):
        # saved as float32
        assert again["generators"]["fitted"]["deviation"][key] == pytest.approx(f["deviation"][key], rel=1e-5)
    assert again["generators"]["raw"]["deviation"] is None
    with pytest.raises(ValueError, match="raw"):
        pp.saved_generators({"fitted/00/0/shown": walk})
