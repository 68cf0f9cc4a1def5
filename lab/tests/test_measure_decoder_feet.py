"""lab/scripts/vae/measure_decoder_feet.py: the latent perturbations of issue 20's decoder-robustness measure (their units
and identities), the worst-bone column, and the whole script on the tiny corpus with a tiny random VAE."""
from __future__ import annotations

import argparse

import numpy as np
import pytest

from _lab import load_script

pytestmark = pytest.mark.usefixtures("single_thread")


@pytest.fixture(scope="module")
def M():
    return load_script("measure_decoder_feet")


def _latents(seed: int = 0) -> list[np.ndarray]:
    rng = np.random.default_rng(seed)
    scale = np.array([0.5, 2.0, 1.0, 3.0], np.float32)
    return [(rng.normal(size=(n, 7, 4)) * scale + [1.0, -2.0, 0.0, 0.5]).astype(np.float32) for n in (30, 45, 60)]


@pytest.mark.parametrize("spec, expected", [("noise:0.5", ("noise", 0.5)), ("scale:2", ("scale", 2.0)),
                                            ("scale:0", ("scale", 0.0))])
def test_perturbation_specs_parse(M, spec, expected):
    assert M.parse_perturbation(spec) == expected


@pytest.mark.parametrize("spec", ["noise", "noise:abc", "scale:-1", "shift:1", "noise:nan", ""])
def test_bad_perturbation_specs_name_the_spec(M, spec):
    with pytest.raises(argparse.ArgumentTypeError, match="bad --perturb"):
        M.parse_perturbation(spec)


def test_identity_perturbations_change_nothing(M):
    z = _latents()
    for kind, amount in (("noise", 0.0), ("scale", 1.0)):
        for a, b in zip(z, M.perturb_latents(z, kind, amount)):
            np.testing.assert_allclose(b, a, atol=1e-5)


def test_scale_multiplies_the_deviation_from_the_pooled_mean(M):
    z = _latents()
    mu = np.concatenate([x.reshape(-1, 4) for x in z]).mean(0)
    out = M.perturb_latents(z, "scale", 2.0)
    for a, b in zip(z, out):
        np.testing.assert_allclose(b - mu, 2.0 * (a - mu), rtol=1e-5, atol=1e-5)
    flat_in = np.concatenate([x.reshape(-1, 4) for x in z])
    flat_out = np.concatenate([x.reshape(-1, 4) for x in out])
    np.testing.assert_allclose(flat_out.std(0), 2.0 * flat_in.std(0), rtol=1e-5)


def test_noise_is_in_units_of_each_channels_own_std_and_seeded(M):
    z = _latents()
    sd = np.concatenate([x.reshape(-1, 4) for x in z]).std(0)
    out = M.perturb_latents(z, "noise", 0.5, seed=3)
    added = np.concatenate([(b - a).reshape(-1, 4) for a, b in zip(z, out)])
    np.testing.assert_allclose(added.std(0) / sd, 0.5, rtol=0.1)          # 945 draws per channel
    assert np.abs(added.mean(0) / sd).max() < 0.1
    again = M.perturb_latents(z, "noise", 0.5, seed=3)
    assert all(np.array_equal(a, b) for a, b in zip(out, again))
    assert not np.array_equal(out[0], M.perturb_latents(z, "noise", 0.5, seed=4)[0])


def test_measure_reports_the_worst_bone_in_cm(M, sample_joints):
    clean = M.measure([sample_joints])
    assert clean["bone_max_cm"] < 0.01                           # the real sample keeps its bones
    stretched = sample_joints.copy()
    forearm = sample_joints[40, 21] - sample_joints[40, 19]      # right elbow -> right wrist
    stretched[40, 21] += 0.1 * forearm / np.linalg.norm(forearm)  # one forearm 10 cm longer in one frame
    r = M.measure([stretched], [sample_joints])
    assert r["bone_max_cm"] == pytest.approx(10.0, abs=0.1)
    assert r["bone_p95_cm"] < 0.01 and 0.0 < r["mpjpe_cm"] < 0.01 * 100


def test_script_prints_a_row_per_vae_and_perturbation(M, make_tiny_pipeline, tiny_procedural_corpus, tmp_path,
                                                      capsys):
    weights = make_tiny_pipeline(seed=0).save_pretrained(tmp_path / "w")
    assert M.main(["--data", str(tiny_procedural_corpus), "--vae", str(weights), "--clips", "3",
                   "--perturb", "scale:1", "noise:2"]) == 0
    rows = {line[9:53].strip(): line[53:].split() for line in capsys.readouterr().out.splitlines()[1:]}
    assert set(rows) == {"(the clips)", str(weights)[-44:], f"{weights} scale 1"[-44:], f"{weights} noise 2"[-44:]}
    plain, same, noisy = rows[str(weights)[-44:]], rows[f"{weights} scale 1"[-44:]], rows[f"{weights} noise 2"[-44:]]
    assert same == plain                                          # scale 1 decodes the posterior means again
    assert noisy != plain
    assert float(rows["(the clips)"][-1]) < 0.01                  # the corpus keeps its bones


def test_a_probe_encodes_the_clips_once_for_all_its_perturbation_rows(M, make_tiny_pipeline, tiny_procedural_corpus,
                                                                       tmp_path):
    weights = make_tiny_pipeline(seed=0).save_pretrained(tmp_path / "w")
    clips = M.load_clips(tiny_procedural_corpus, 3)
    probe = M.DecoderProbe(str(weights), clips)
    calls = []
    encode = probe.vae.encode
    probe.vae.encode = lambda *a, **k: calls.append(1) or encode(*a, **k)
    rows = [probe.perturbed("scale", 1.0), probe.perturbed("noise", 0.5), probe.perturbed("scale", 2.0)]
    assert len(calls) == len(clips)                               # one encoding per clip, not per row
    for a, b in zip(rows[0], M.reconstruct(str(weights), clips)):
        np.testing.assert_allclose(a, b, atol=1e-4)               # scale 1 = the batched clean reconstruction
    assert all(r.shape == c.shape for r, c in zip(rows[1], clips))
