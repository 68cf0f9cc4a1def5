"""The package map and the layering rules hold: every module named in ``salad_core.__init__``'s map,
every code location it gives for the paper's equations and Algorithm 1 exists, ``salad_viz`` reads only
what :data:`VIZ_MAY_IMPORT` lists of ``salad_core``, ``salad_core`` draws nothing outside its command line (the
``salad_core.cli`` package), and the attention measures do not reach into the procedural corpus. Static checks
(AST), no model runs.

The layer order (docs/architecture.md), checked for top-level and function-local imports alike in every
``.py`` of the repository and every notebook code cell: ``salad_core`` (bottom) <- ``salad_viz`` <- the lab
(``lab/``: ``salad_lab``, its scripts and tests); the toolkit's tests, scripts, benchmarks and notebooks use
``salad_core`` and ``salad_viz`` and never the lab; no import cycle between packages. The command line
(``salad_core/cli/``, :data:`ALLOWED_UPWARD`) sits on top: it alone of ``salad_core`` imports ``salad_viz`` (to draw
figures), and nothing below it imports it (no other ``salad_core`` module except the ``python -m`` entry points
``__main__.py``, and never ``salad_viz``). ``salad_core/**`` (code, JSON, model cards) names no issue numbers and no
machine paths; notebooks never read ``lab/``.
:func:`layout_violations` is the checker; the tests run it on this repository (no violation) and on small
trees with a deliberately wrong import (each one found).
"""
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


#: What salad_viz may read of salad_core, each with its reason (salad_viz takes arrays, not models).
VIZ_MAY_IMPORT = {
    "salad_core.skeleton": "the layout of the arrays it draws (joints, parts, chains)",
    "salad_core.bvh.reader": "export_bvh reads back the BVH it wrote to measure its exactness (a numpy-only parser)",
    "salad_core.limits": "the limits on arrays from outside (joints within a kilometre; a numpy-only module)",
}


def test_salad_viz_depends_only_on_the_skeleton():
    for path in VIZ.glob("*.py"):
        ours = {m for m in _imports(path) if m.startswith("salad_core")}
        assert ours <= set(VIZ_MAY_IMPORT), f"{path.name} imports {sorted(ours)}"


def test_salad_core_draws_nothing_outside_its_command_line():
    for path in ROOT.rglob("*.py"):
        if (ROOT / "cli") in path.parents:
            continue
        drawing = {m for m in _imports(path) if m.split(".")[0] == "matplotlib"}
        assert not drawing, f"{path.relative_to(ROOT)} imports {sorted(drawing)}: figures belong in salad_viz"


@pytest.mark.parametrize("module", ["attention/measure.py", "part_activity.py"])
def test_measures_do_not_reach_into_the_procedural_corpus(module):
    assert not {m for m in _imports(ROOT / module) if m.startswith("salad_core.data.procedural")}



# ------------------------------------------------------------------------------------------- layer order
REPO = ROOT.parent
#: Our packages, bottom first, and the packages of ours each may import.
LAYERS = {"salad_core": set(), "salad_viz": {"salad_core"}, "salad_lab": {"salad_core", "salad_viz"}}
#: Code trees that are not installed and what they may import of ours (the lab's tree holds ``salad_lab``).
TREES = {"tests": {"salad_core", "salad_viz"}, "scripts": {"salad_core", "salad_viz"},
         "bench": {"salad_core", "salad_viz"}, "notebooks": {"salad_core", "salad_viz"},
         "lab": {"salad_core", "salad_viz", "salad_lab"}}
#: The known upward imports (salad_core -> salad_viz), each folder with its reason: the command line draws figures
#: with salad_viz. A salad_viz import anywhere else in salad_core is a violation.
ALLOWED_UPWARD = {
    "salad_core/cli/": "the salad command line writes figures (heatmaps, GIFs, the CFG-sweep plot) with salad_viz",
}
#: The command line, at the top: only the entry points (``python -m salad_core.train``, ``.bench``), the tests,
#: scripts, notebooks and the lab import it; no other module of salad_core, and never salad_viz.
CLI = "salad_core.cli"


def _upward_allowed(rel: str) -> bool:
    return any(rel.startswith(folder) for folder in ALLOWED_UPWARD)
#: Files of salad_core/** whose issue references are being edited by other work in progress; each must be
#: cleaned when that work lands (the list may only shrink).
PENDING_ISSUE_REFERENCES: dict[str, str] = {}
ISSUE_NUMBER = re.compile(r"\bissues? #?\d+|(?<![\w#&/.])#\d+\b(?![.\d])", re.I)
MACHINE_PATH = re.compile(r"/root/|/home/|~/salad-runs")
NOTEBOOK_READS_LAB = re.compile(r"""["'](?:\.\./)*lab(?:/|["'])|/\s*["']lab["']""")


def _package_of(module: str) -> str | None:
    top = module.split(".")[0]
    return top if top in LAYERS else None


def _imported_modules(tree: ast.AST) -> set[str]:
    """Every absolute module an AST imports, anywhere (top level, functions, classes), including
    ``importlib.import_module("...")`` and ``__import__("...")`` with a constant name."""
    out = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            out |= {a.name for a in node.names}
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            out.add(node.module)
        elif isinstance(node, ast.Call) and node.args and isinstance(node.args[0], ast.Constant) \
                and isinstance(node.args[0].value, str):
            f = node.func
            name = f.attr if isinstance(f, ast.Attribute) else f.id if isinstance(f, ast.Name) else ""
            if name in ("import_module", "__import__"):
                out.add(node.args[0].value)
    return out


def _notebook_sources(path: Path) -> list[str]:
    import json

    cells = json.loads(path.read_text(encoding="utf-8"))["cells"]
    out = []
    for cell in cells:
        if cell["cell_type"] == "code":
            src = "".join(cell["source"]) if isinstance(cell["source"], list) else cell["source"]
            out.append("\n".join("" if re.match(r"^\s*[%!]", line) else line for line in src.splitlines()))
    return out


def _owner(rel: str) -> str | None:
    """The package (``salad_core``, ``salad_viz``, ``salad_lab``) or tree a repository file belongs to."""
    first = rel.split("/")[0]
    if first in ("salad_core", "salad_viz"):
        return first
    if rel.startswith("lab/salad_lab/"):
        return "salad_lab"
    return first if first in TREES else None


def layout_violations(root: Path) -> list[str]:
    """Every breach of the layer order under ``root`` (a repository checkout), as readable lines."""
    out: list[str] = []
    edges: dict[str, set[str]] = {p: set() for p in LAYERS}
    files = [p for p in root.rglob("*.py") if not {".venv", "node_modules", "build"} & set(p.relative_to(root).parts)]
    sources: list[tuple[str, str]] = [(p.relative_to(root).as_posix(), p.read_text(encoding="utf-8")) for p in files]
    notebooks = sorted((root / "notebooks").glob("*.ipynb")) if (root / "notebooks").is_dir() else []
    for nb in notebooks:
        rel = nb.relative_to(root).as_posix()
        for i, src in enumerate(_notebook_sources(nb)):
            sources.append((f"{rel} (code cell {i})", src))
            if NOTEBOOK_READS_LAB.search(src):
                out.append(f"{rel} code cell {i} reads lab/: notebooks use the shipped records (salad_core/weights)")
    for rel, text in sources:
        owner = _owner(rel)
        if owner is None:
            continue
        allowed = LAYERS.get(owner, TREES.get(owner, set()))
        for module in sorted(_imported_modules(ast.parse(text))):
            if (module == CLI or module.startswith(CLI + ".")) and owner in ("salad_core", "salad_viz") \
                    and not _upward_allowed(rel) and not rel.endswith("/__main__.py"):
                out.append(f"{rel} imports {module}: the command line is the top of the toolkit; only its own "
                           "modules, the python -m entry points (__main__.py), tests, scripts and the lab import it")
            target = _package_of(module)
            if target is None or target == owner:
                continue
            if owner == "salad_core" and target == "salad_viz" and _upward_allowed(rel):
                continue                       # the command line: not an edge of the package graph either
            if target not in allowed:
                out.append(f"{rel} imports {module}: {owner} may import only {sorted(allowed) or 'none of ours'}")
            if owner in edges:
                edges[owner].add(target)
    out += [f"import cycle between packages: {' -> '.join(c)}" for c in _cycles(edges)]
    return out


def _cycles(edges: dict[str, set[str]]) -> list[list[str]]:
    """The cycles of a small directed graph (each found once, from its first node in sorted order)."""
    found = []

    def walk(path: list[str]) -> None:
        for nxt in sorted(edges.get(path[-1], ())):
            if nxt == path[0]:
                found.append(path + [nxt])
            elif nxt not in path and nxt > path[0]:
                walk(path + [nxt])

    for start in sorted(edges):
        walk([start])
    return found


def text_violations(root: Path, pending: dict[str, str] | None = None) -> list[str]:
    """Issue numbers and machine paths in ``salad_core/**`` (code, JSON, model cards)."""
    pending = PENDING_ISSUE_REFERENCES if pending is None else pending
    out = []
    for path in sorted((root / "salad_core").rglob("*")):
        if path.suffix not in (".py", ".json", ".md") or "__pycache__" in path.parts:
            continue
        rel = path.relative_to(root).as_posix()
        for n, line in enumerate(path.read_text(encoding="utf-8").splitlines(), start=1):
            if MACHINE_PATH.search(line):
                out.append(f"{rel}:{n}: a machine path: {line.strip()[:120]}")
            if ISSUE_NUMBER.search(line) and rel not in pending:
                out.append(f"{rel}:{n}: an issue number: {line.strip()[:120]}")
    return out


def test_the_repository_keeps_the_layer_order():
    assert layout_violations(REPO) == []


def test_salad_core_names_no_issue_numbers_or_machine_paths():
    assert text_violations(REPO) == []


def test_the_pending_issue_references_are_the_other_works_files():
    """The list of files allowed to keep issue numbers for now only names existing files that still have them."""
    for rel in PENDING_ISSUE_REFERENCES:
        assert (REPO / rel).is_file(), f"{rel} is gone: remove it from PENDING_ISSUE_REFERENCES"


def _tree(tmp_path: Path, files: dict[str, str]) -> Path:
    for rel, text in files.items():
        (tmp_path / rel).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / rel).write_text(text)
    return tmp_path


#: A tiny repository in the right order: viz reads the skeleton, the lab and the tests read the toolkit.
GOOD = {
    "salad_core/__init__.py": "",
    "salad_core/skeleton.py": "import numpy\n",
    "salad_core/cli/__init__.py": "def main():\n    import salad_viz\n",   # the command line: allowed
    "salad_core/cli/eval.py": "from salad_viz.plots import plot_cfg_sweep\n",
    "salad_core/train/__main__.py": "from salad_core.cli.train import main\n",  # an entry point
    "salad_viz/__init__.py": "from salad_core.skeleton import numpy\n",
    "lab/salad_lab/__init__.py": "import salad_core\nimport salad_viz\n",
    "tests/test_x.py": "import salad_core.skeleton\n",
}


def test_the_checker_passes_a_tree_in_the_right_order(tmp_path):
    assert layout_violations(_tree(tmp_path, GOOD)) == []


def test_the_checker_fails_on_a_wrong_way_import_inside_a_function(tmp_path):
    """The deliberate wrong-way import: a salad_core module that is not a command line imports salad_viz inside a
    function; the checker names it, and the package cycle it makes."""
    bad = {**GOOD, "salad_core/motion.py": "def draw(x):\n    from salad_viz import plot\n    return plot(x)\n"}
    found = layout_violations(_tree(tmp_path, bad))
    assert any(v.startswith("salad_core/motion.py imports salad_viz") for v in found), found
    assert any("import cycle" in v and "salad_core" in v and "salad_viz" in v for v in found), found


@pytest.mark.parametrize("rel, text", [
    ("salad_core/eval/protocol.py", "def f():\n    from salad_core.cli._common import UserError\n"),
    ("salad_core/train/common.py", "import salad_core.cli\n"),
    ("salad_viz/plots.py", "from salad_core.cli import main\n"),
])
def test_the_checker_fails_when_a_lower_module_imports_the_command_line(tmp_path, rel, text):
    """The command line is the top: a library module or salad_viz importing it is named."""
    found = layout_violations(_tree(tmp_path, {**GOOD, rel: text}))
    assert any(v.startswith(f"{rel} imports salad_core.cli") and "top of the toolkit" in v for v in found), found


def test_the_checker_fails_on_salad_viz_outside_the_command_line_package(tmp_path):
    """A file beside the package (salad_core/cli_tools.py) is not the command line."""
    found = layout_violations(_tree(tmp_path, {**GOOD, "salad_core/cli_tools.py": "import salad_viz\n"}))
    assert any(v.startswith("salad_core/cli_tools.py imports salad_viz") for v in found), found


@pytest.mark.parametrize("rel, text, what", [
    ("salad_core/io.py", "def f():\n    import salad_lab.card\n", "salad_core/io.py imports salad_lab.card"),
    ("salad_viz/plots.py", "import importlib\nm = importlib.import_module('salad_lab')\n", "salad_viz/plots.py imports salad_lab"),
    ("tests/test_y.py", "from salad_lab.reading import verdict\n", "tests/test_y.py imports salad_lab.reading"),
    ("scripts/tool.py", "import salad_lab\n", "scripts/tool.py imports salad_lab"),
])
def test_the_checker_fails_when_the_toolkit_imports_the_lab(tmp_path, rel, text, what):
    found = layout_violations(_tree(tmp_path, {**GOOD, rel: text}))
    assert any(v.startswith(what) for v in found), found


def test_the_checker_fails_on_a_notebook_that_reads_the_lab(tmp_path):
    import json

    cell = {"cell_type": "code", "source": ["import json\n", "json.load(open('../lab/records/x.json'))\n"],
            "metadata": {}, "outputs": [], "execution_count": None}
    (tmp_path / "notebooks").mkdir()
    (tmp_path / "notebooks" / "99_x.ipynb").write_text(json.dumps({"cells": [cell]}))
    found = layout_violations(_tree(tmp_path, GOOD))
    assert found and "reads lab/" in found[0], found


def test_the_text_check_finds_issue_numbers_and_machine_paths(tmp_path):
    root = _tree(tmp_path, {"salad_core/a.py": '"""Fixed for issue 22."""\n',
                            "salad_core/weights/x/runs.json": '{"data": "/root/salad-runs/v3/corpus"}\n',
                            "salad_core/weights/x/MODEL_CARD.md": "See #22; `caption#word#0.0#0.0` is a format.\n",
                            "salad_core/b.py": "# colour '#1f77b4', heading ## 2\n"})
    found = text_violations(root, pending={})
    assert [v.split(":")[0] for v in found] == ["salad_core/a.py", "salad_core/weights/x/MODEL_CARD.md",
                                                "salad_core/weights/x/runs.json"], found
