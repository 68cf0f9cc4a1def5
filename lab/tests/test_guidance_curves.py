"""lab/scripts/guidance/guidance_curves.py (issue 20's guidance curves): the relative latent spread's identities, the weight list's
errors, and the whole script on the tiny corpus with a tiny random pipeline (the plumbing, not the shipped figures)."""
from __future__ import annotations

import numpy as np
import pytest

from _lab import load_script

pytestmark = pytest.mark.usefixtures("single_thread")


@pytest.fixture(scope="module")
def G():
    return load_script("guidance_curves")


def test_relative_spread_is_one_on_the_data_and_scales_with_the_deviation(G):
    rng = np.random.default_rng(0)
    ref = rng.normal(size=(500, 4)) * [1.0, 2.0, 0.5, 3.0] + [1.0, -1.0, 0.0, 2.0]
    assert G.relative_spread(ref, ref) == pytest.approx(1.0)
    mu = ref.mean(0)
    assert G.relative_spread(mu + 1.5 * (ref - mu), ref) == pytest.approx(1.5)
    assert G.relative_spread(np.tile(mu, (7, 1)), ref) == pytest.approx(0.0)


@pytest.mark.parametrize("text, message", [("", "empty"), ("1,x", "must be comma-separated")])
def test_bad_weight_lists_are_refused_by_name(G, text, message):
    with pytest.raises(SystemExit, match=message):
        G.parse_scales(text)


def test_script_prints_a_spread_per_weight_and_a_rise_per_seed(G, make_tiny_pipeline, tiny_procedural_corpus,
                                                              tmp_path, capsys):
    weights = make_tiny_pipeline(seed=0).save_pretrained(tmp_path / "w")
    assert G.main(["--data", str(tiny_procedural_corpus), "--weights", str(weights), "--scales", "1,3",
                   "--clips", "2", "--seeds", "2", "--steps", "2", "--num-prompts", "3"]) == 0
    out = capsys.readouterr().out.splitlines()
    spreads = [line for line in out if line.strip().startswith("w ")]
    assert len(spreads) == 2 and all(float(line.split(":")[1]) > 0 for line in spreads)
    rises = [line for line in out if any(p in line for p in G.JUMP_PROMPTS)]
    assert len(rises) == 3 * 2 and all(len(line.split(":")[1].split()) == 2 for line in rises)
