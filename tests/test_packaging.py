"""The install files agree with each other: pyproject.toml, requirements.txt, environment.yml."""
from __future__ import annotations

import re
import tomllib
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def _name(req: str) -> str:
    return re.split(r"[<>=!~\[; ]", req.strip(), maxsplit=1)[0].lower().replace("_", "-")


def _requirements() -> dict[str, str]:
    out = {}
    for line in (ROOT / "requirements.txt").read_text().splitlines():
        line = line.split("#", 1)[0].strip()
        if line:
            out[_name(line)] = line
    return out


def _environment_pip() -> dict[str, str]:
    lines = (ROOT / "environment.yml").read_text().splitlines()
    out, in_pip = {}, False
    for line in lines:
        s = line.strip()
        if s == "- pip:":
            in_pip = True
            continue
        if in_pip and s.startswith("- "):
            item = s[2:].strip()
            if not item.startswith("-e"):
                out[_name(item)] = item
    return out


def test_environment_yml_matches_requirements():
    req, env = _requirements(), _environment_pip()
    assert req == env, f"only in requirements.txt: {sorted(set(req) - set(env))}; only in environment.yml: {sorted(set(env) - set(req))}; differing pins: {[k for k in req if k in env and req[k] != env[k]]}"


def test_environment_yml_python_311():
    text = (ROOT / "environment.yml").read_text()
    assert re.search(r"^\s*-\s*python=3\.11\s*$", text, re.M)


def test_pyproject_dependencies_are_pinned_in_requirements():
    meta = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    deps = [_name(d) for d in meta["dependencies"]]
    optional = {"deepmimic"}  # large optional extras, deliberately not in the default install
    extras = [_name(d) for name, group in meta["optional-dependencies"].items() if name not in optional for d in group]
    req = _requirements()
    missing = [d for d in deps + extras if d not in req]
    assert not missing, f"pyproject dependencies not pinned in requirements.txt: {missing}"
    # torch must be the CPU build on this machine: the exact version on its disk
    assert req["torch"] == "torch==2.13.0"


def test_console_script_declared():
    meta = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    assert meta["scripts"]["salad"] == "salad_core.cli:main"


def test_version_is_one_number_everywhere():
    import salad_core

    root = Path(__file__).resolve().parents[1]
    version = tomllib.loads((root / "pyproject.toml").read_text())["project"]["version"]
    assert salad_core.__version__ == version
    major_minor = ".".join(version.split(".")[:2])
    assert f"(version {major_minor})" in (root / "README.md").read_text()


def test_the_lab_is_not_packaged():
    """The wheel holds the toolkit only: no package of lab/ is found, and the package data globs stay inside
    salad_core/weights (the ablation study's weights ship once, there)."""
    from setuptools import find_packages

    cfg = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]
    packages = find_packages(where=str(ROOT), include=cfg["packages"]["find"]["include"])
    assert packages and all(p.split(".")[0] in ("salad_core", "salad_viz") for p in packages), packages
    assert not any(p.startswith(("lab", "salad_lab")) for p in packages)
    for pkg, globs in cfg["package-data"].items():
        assert pkg == "salad_core" and all(not g.startswith("..") for g in globs)


def test_readme_is_a_short_users_guide():
    text = (ROOT / "README.md").read_text()
    assert len(text.splitlines()) <= 150
    assert "bash scripts/setup.sh" in text and ".venv/bin/salad demo --out demo_out" in text
    assert '-m "not slow"' in text


def test_the_slow_tier_names_existing_tests():
    """Every module and test tests/conftest.py marks slow exists (a renamed test would leave the fast tier slow)."""
    import ast

    import conftest

    tests = ROOT / "tests"
    for module in conftest.SLOW_MODULES:
        assert (tests / f"{module}.py").is_file(), module
    for key in conftest.SLOW_TESTS:
        file, name = key.split("::")
        tree = ast.parse((tests / file).read_text())
        assert name in {n.name for n in tree.body if isinstance(n, ast.FunctionDef)}, key
