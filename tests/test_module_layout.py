"""The package map and the layering rules hold: every module named in ``salad_core.__init__``'s map,
every code location it gives for the paper's equations and Algorithm 1 exists, ``salad_viz`` uses
``salad_core.skeleton`` only, ``salad_core`` draws nothing outside its command lines, and the
attention measures do not reach into the procedural corpus. Static checks (AST), no model runs."""
from __future__ import annotations

import ast
import importlib
import re
from pathlib import Path

import pytest

import salad_core

ROOT = Path(salad_core.__file__).parent
VIZ = ROOT.parent / "salad_viz"
DOC = salad_core.__doc__


def _imports(path: Path) -> set[str]:
    """Every module a file imports, anywhere in it (top level or inside functions)."""
    out = set()
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.Import):
            out |= {a.name for a in node.names}
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            out.add(node.module)
    return out


def _section(title: str) -> str:
    start = DOC.index(title)
    return DOC[start:]


def test_the_map_names_every_module_and_subpackage():
    listed = {line.split()[0] for line in _section("Modules\n").split("\n\n")[0].splitlines()[2:] if line.strip()}
    present = {p.stem for p in ROOT.glob("*.py") if p.stem != "__init__"}
    present |= {p.name for p in ROOT.iterdir() if p.is_dir() and not p.name.startswith("__")}
    assert listed == present, f"missing from the map: {present - listed}; no longer in the tree: {listed - present}"


def _resolve(dotted: str):
    parts = dotted.split(".")
    for cut in range(len(parts), 0, -1):
        try:
            obj = importlib.import_module(".".join(parts[:cut]))
        except ModuleNotFoundError:
            continue
        for attr in parts[cut:]:
            obj = getattr(obj, attr)
        return obj
    raise ModuleNotFoundError(dotted)


def test_every_equation_and_algorithm_step_points_at_existing_code():
    refs = re.findall(r"(salad_core(?:\.\w+)+)\s*$", _section("The paper, equation by equation"), flags=re.M)
    assert len(refs) >= 25
    equations = re.findall(r"^eqs?\. ([\d-]+)", _section("The paper, equation by equation"), flags=re.M)
    numbers = {n for e in equations for n in (range(int(e.split("-")[0]), int(e.split("-")[-1]) + 1))}
    assert numbers == set(range(1, 14)), f"SALAD numbers equations 1-13; the map covers {sorted(numbers)}"
    for ref in refs:
        assert callable(_resolve(ref)), ref


def test_salad_viz_depends_only_on_the_skeleton():
    for path in VIZ.glob("*.py"):
        ours = {m for m in _imports(path) if m.startswith("salad_core")}
        assert ours <= {"salad_core.skeleton"}, f"{path.name} imports {sorted(ours)}"


def test_salad_core_draws_nothing_outside_its_command_lines():
    clis = {ROOT / "cli.py", ROOT / "eval" / "cli.py", ROOT / "train" / "cli.py"}
    for path in ROOT.rglob("*.py"):
        if path in clis:
            continue
        drawing = {m for m in _imports(path) if m.split(".")[0] == "matplotlib"}
        assert not drawing, f"{path.relative_to(ROOT)} imports {sorted(drawing)}: figures belong in salad_viz"


@pytest.mark.parametrize("module", ["attention/measure.py", "part_activity.py"])
def test_measures_do_not_reach_into_the_procedural_corpus(module):
    assert not {m for m in _imports(ROOT / module) if m.startswith("salad_core.data.procedural")}
