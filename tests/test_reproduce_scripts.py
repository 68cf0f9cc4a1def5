"""One reproduce script per shipped artefact (scripts/reproduce_*.sh): each runs in ``--dry-run``, prints
commands that name existing configs and scripts, writes outside ``salad_core/weights`` by default and refuses
to write into it; each config starts with the command that trains it; each model card cites its script."""
from __future__ import annotations

import json
import shlex
import subprocess
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
WEIGHTS = REPO / "salad_core" / "weights"

#: shipped artefact -> (reproduce script, the configs it trains with)
ARTEFACTS = {
    "salad": ("reproduce_salad.sh", ["configs/salad-0.3/vae.json", "configs/salad-0.3/denoiser.json"]),
    "general_vae": ("reproduce_general_vae.sh", ["configs/general-vae.json"]),
    "keymotion": ("reproduce_keymotion.sh", ["configs/keymotion-0.2.json"]),
    "evaluator": ("reproduce_evaluator.sh", ["configs/evaluator.json"]),
}


def _dry_run(script: str, *args: str) -> subprocess.CompletedProcess:
    return subprocess.run(["bash", str(REPO / "scripts" / script), "--dry-run", *args], capture_output=True,
                          text=True, timeout=60, cwd=REPO)


def test_every_shipped_artefact_has_a_reproduce_script():
    shipped = {p.name for p in WEIGHTS.iterdir() if p.is_dir()} - {"ablations"}   # the lab's study (lab/README.md)
    assert shipped == set(ARTEFACTS)


@pytest.mark.parametrize("artefact", sorted(ARTEFACTS))
def test_dry_run_prints_commands_that_name_existing_configs(artefact):
    script, configs = ARTEFACTS[artefact]
    res = _dry_run(script)
    assert res.returncode == 0, res.stderr
    commands = [shlex.split(line) for line in res.stdout.splitlines() if line.strip()]
    assert commands, "the dry run printed no command"
    named = [c[c.index("--config") + 1] for c in commands if "--config" in c]
    if artefact == "evaluator":       # its trainer takes options: the script reads them from the config
        named = ["configs/evaluator.json"]
        text = res.stdout
        for key, value in json.loads((REPO / "configs/evaluator.json").read_text())["args"].items():
            assert f"--{key} {value}" in text
    assert named == configs
    for word in (w for c in commands for w in c):
        if word.startswith(("configs/", "scripts/")):
            assert (REPO / word).is_file(), f"{script} names {word}, which does not exist"
    outs = [c[c.index(flag) + 1] for c in commands for flag in ("--out", "--export") if flag in c]
    assert outs and all(o.startswith(f"runs/reproduce/{artefact}/") for o in outs), outs


@pytest.mark.parametrize("artefact", sorted(ARTEFACTS))
def test_refuses_to_write_into_the_shipped_weights(artefact):
    res = _dry_run(ARTEFACTS[artefact][0], f"salad_core/weights/{artefact}")
    assert res.returncode != 0 and "refusing" in res.stderr
    assert not res.stdout.strip()


@pytest.mark.parametrize("artefact", sorted(ARTEFACTS))
def test_configs_start_with_their_command_and_cards_cite_the_script(artefact):
    script, configs = ARTEFACTS[artefact]
    for config in configs:
        doc = json.loads((REPO / config).read_text())
        first = next(iter(doc))
        assert first == "_command", f"{config} starts with {first!r}"
        assert config in doc["_command"] or artefact == "evaluator"
        assert doc["_reproduce"].startswith(f"bash scripts/{script}")
    card = (WEIGHTS / artefact / "MODEL_CARD.md").read_text()
    assert f"bash scripts/{script}" in card


def test_the_salad_vae_recipe_is_the_general_vae_recipe():
    """SALAD 0.3's VAE is the general motion VAE (in fp16): its two configs cannot drift apart."""
    a, b = (json.loads((REPO / p).read_text()) for p in ("configs/salad-0.3/vae.json", "configs/general-vae.json"))
    assert {k: v for k, v in a.items() if not k.startswith("_")} == {k: v for k, v in b.items() if not k.startswith("_")}


def test_scripts_folder_holds_at_most_ten_files():
    files = [p for p in (REPO / "scripts").iterdir() if p.is_file()]
    assert len(files) <= 10, sorted(p.name for p in files)
