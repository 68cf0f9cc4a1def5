"""salad_lab.denoising: the denoising-error probe's record, summarised per variant and read back (the records of
lab/scripts/ablations/ablation_denoising_error.py; moved from tests/test_denoising_error.py)."""
from __future__ import annotations

import numpy as np
import pytest


def test_the_scripts_record_pairs_variants_only_where_their_latents_compare():
    import json

    from salad_lab.denoising import denoising_markdown, summarise
    from salad_core.eval.denoising_error import DenoisingError

    def result(kind, shape, latent, joints):
        return DenoisingError((10,), 7.5, kind, shape, ["a", "b", "c"],
                              latent={"cond": {10: np.asarray(latent)}}, joints={"cond": {10: np.asarray(joints)}})

    results = {"full": result("v_prediction", (7, 4), [1.0, 2.0, 3.0], [0.01, 0.02, 0.03]),
               "x0": result("sample", (7, 4), [2.0, 3.0, 4.5], [0.02, 0.02, 0.05]),
               "no_st": result("v_prediction", (1, 16), [0.5, 0.5, 0.5], [0.03, 0.03, 0.03])}
    rows = summarise(results, "full")
    assert "paired_vs_full" not in rows["full"]
    mean, half = rows["x0"]["paired_vs_full"]["latent"]["cond"][10]
    assert mean == pytest.approx(9.5 / 3 - 2.0) and half > 0   # positive: the first (full) is better
    assert set(rows["no_st"]["paired_vs_full"]) == {"joints"}          # another VAE: no latent comparison
    assert rows["no_st"]["paired_vs_full"]["joints"]["cond"][10][0] == pytest.approx(0.01)
    record = json.loads(json.dumps({"first": "full", "timesteps": [10], "variants": rows}))
    table = denoising_markdown(record, "joints", "cond")
    assert "| x0 | 3 (+1 ± " in table and "| full | 2 |" in table


def test_the_text_response_is_recovered_exactly_from_the_three_errors():
    """Made-up estimates with a known |c - u|^2 and <u - x0, c - u>: their three mean errors give both back."""
    from salad_lab.denoising import text_response, text_response_markdown

    rng = np.random.default_rng(0)
    x0, u_err, delta = rng.normal(size=(3, 5, 40))              # 5 clips x 40 latent elements
    delta *= 0.3
    u = x0 + u_err
    c = u + delta
    w = 7.5
    g = u + w * (c - u)
    mse = lambda e: float(((e - x0) ** 2).mean(axis=1).mean())
    record = {"guidance_scale": w, "timesteps": [500],
              "variants": {"full": {"means": {"latent": {"cond": {"500": mse(c)}, "uncond": {"500": mse(u)},
                                                         "guided": {"500": mse(g)}}}}}}
    got = text_response(record, "full")["500"]
    want_d = float((delta ** 2).mean(axis=1).mean())
    want_x = float((u_err * delta).mean(axis=1).mean())
    np.testing.assert_allclose(got["response"], want_d, rtol=1e-9)
    np.testing.assert_allclose(got["relative"], want_d / mse(c), rtol=1e-9)
    np.testing.assert_allclose(got["cosine"], want_x / np.sqrt(mse(u) * want_d), rtol=1e-9)
    assert f"{want_d / mse(c):.3f}" in text_response_markdown(record)
    record["variants"]["full"]["means"]["latent"].pop("uncond")
    with pytest.raises(ValueError, match="--unconditional"):
        text_response(record, "full")
    with pytest.raises(ValueError, match="guidance weight 1"):
        text_response({**record, "guidance_scale": 1.0}, "full")
