"""lab/scripts/editing/inpaint_prior_fidelity_probe.py: the prior-fidelity distance and the rankings it compares
(pure functions; the sampling is the product's ``pipe.edit``, tested in tests/)."""
from __future__ import annotations

import numpy as np
import pytest

from _lab import load_script

probe = load_script("inpaint_prior_fidelity_probe")


def test_fidelity_is_the_root_relative_distance_over_the_span_against_the_priors_frames():
    rng = np.random.default_rng(0)
    prior = rng.normal(size=(40, 22, 3))
    edited = rng.normal(size=(120, 22, 3))
    # the span's frames 40..56 are the prior's frames 8..24 moved bodily: root-relative they are the same
    edited[40:56] = prior[8:24] + np.array([3.0, 0.0, -2.0])
    assert probe.fidelity_cm(edited, prior, (40, 56), 8) == pytest.approx(0.0, abs=1e-9)
    # a pose change of 10 cm on every non-root joint of every frame reads 10 * 21 / 22 cm on average
    edited[40:56, 1:, 1] += 0.10
    assert probe.fidelity_cm(edited, prior, (40, 56), 8) == pytest.approx(10.0 * 21 / 22)


def test_rankings_pick_among_the_smooth_candidates_and_fall_back_to_the_smoothest():
    cands = [dict(seam_ratio=1.2, fidelity_cm=9.0, distance=3.0, vertical_cm=2.0),
             dict(seam_ratio=2.0, fidelity_cm=1.0, distance=1.0, vertical_cm=0.5),  # not smooth: never picked
             dict(seam_ratio=0.8, fidelity_cm=5.0, distance=4.0, vertical_cm=6.0),
             dict(seam_ratio=1.4, fidelity_cm=7.0, distance=2.0, vertical_cm=3.0)]
    assert probe.rankings(cands) == {"seed 0": 0, "most faithful among smooth": 2, "least faithful among smooth": 0,
                                     "evaluator's closest among smooth": 3,
                                     "vertically most faithful among smooth": 0,
                                     "vertically least faithful among smooth": 2}
    rough = [dict(seam_ratio=3.0, fidelity_cm=1.0, distance=1.0, vertical_cm=1.0),
             dict(seam_ratio=2.0, fidelity_cm=9.0, distance=9.0, vertical_cm=9.0)]
    assert set(probe.rankings(rough).values()) == {0, 1} and probe.rankings(rough)["seed 0"] == 0
    assert all(i == 1 for k, i in probe.rankings(rough).items() if k != "seed 0")
