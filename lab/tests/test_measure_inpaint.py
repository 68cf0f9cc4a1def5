"""lab/scripts/editing/measure_inpaint.py: the kept-frames distance with each kept run moved bodily onto the take's
(pure function; the edits themselves are the product's, tested in tests/)."""
from __future__ import annotations

import numpy as np
import pytest

from _lab import load_script

measure = load_script("measure_inpaint")


def _turned(x: np.ndarray, angle: float, shift) -> np.ndarray:
    c, s = np.cos(angle), np.sin(angle)
    out = x.copy()
    out[..., 0] = c * x[..., 0] - s * x[..., 2]
    out[..., 2] = s * x[..., 0] + c * x[..., 2]
    return out + np.asarray(shift)


def test_a_kept_run_turned_and_moved_whole_reads_zero_and_a_pose_change_does_not():
    rng = np.random.default_rng(0)
    src = rng.normal(size=(60, 22, 3))
    ed = src.copy()
    ed[20:40] += 1.0                                               # the regenerated span: anything
    ed[40:] = _turned(src[40:], 1.2, [0.5, 0.0, -2.0])              # after it, the take turned 69 degrees, moved
    kept = list(range(20)) + list(range(40, 60))
    assert measure.segment_aligned_cm(src, ed, kept) == pytest.approx(0.0, abs=1e-9)
    # a per-frame root alignment does see the turn (the joints around the root point elsewhere)
    ra = lambda j: j - j[:, :1]
    assert np.linalg.norm(ra(src)[40:] - ra(ed)[40:], axis=-1).mean() > 0.5
    # one joint lifted 10 cm on every frame after the span: the run's best fit lowers it by 10/22 cm and lifts the
    # other 21 by as much (a vertical shift does not change the fitted turn), over half the kept frames
    ed[40:, 5, 1] += 0.10
    per_frame = 10.0 * 21 / 22 + 21 * 10.0 / 22                    # cm, summed over the 22 joints
    assert measure.segment_aligned_cm(src, ed, kept) == pytest.approx(per_frame * 20 / (40 * 22))
    assert np.isnan(measure.segment_aligned_cm(src, ed, []))


def test_a_turn_inside_one_kept_run_is_not_aligned_away():
    """One rotation per run: kept frames that turn against the take within the run still count."""
    rng = np.random.default_rng(1)
    src = rng.normal(size=(30, 22, 3))
    ed = src.copy()
    ed[15:] = _turned(src[15:], 0.8, [0.0, 0.0, 0.0])             # half of the single run turned
    assert measure.segment_aligned_cm(src, ed, list(range(30))) > 10.0
