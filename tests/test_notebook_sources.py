"""The committed notebooks are the source: what the deleted generator used to guarantee, checked here.

Each notebook must be a valid nbformat 4 document stored without outputs or execution counts, open
with a title, have a parameters cell (QUICK from ``SALAD_QUICK``, outputs under
``SALAD_NOTEBOOK_OUT``) and lint clean: every code cell compiles, no name is used that the notebook
never defines or imports, and no import is left unused. ``ruff check`` runs on them too when ruff
is installed. ``notebooks/README.md`` lists exactly the notebooks there are. Executing them is
``tests/test_notebooks.py``'s job.
"""
from __future__ import annotations

import ast
import builtins
import json
import re
import shutil
import subprocess
import symtable
from pathlib import Path

import pytest

NB_DIR = Path(__file__).resolve().parents[1] / "notebooks"
NOTEBOOKS = sorted(NB_DIR.glob("*.ipynb"))
IDS = [p.stem for p in NOTEBOOKS]

#: Names the IPython kernel provides without an import.
IPYTHON_NAMES = frozenset({"display", "get_ipython"})
#: A line IPython runs but Python cannot parse: line magics and shell escapes.
_MAGIC = re.compile(r"^\s*[%!]")


def _source(cell) -> str:
    src = cell["source"]
    return "".join(src) if isinstance(src, list) else src


def _code_cells(path: Path) -> list[str]:
    nb = json.loads(path.read_text(encoding="utf-8"))
    return [_source(c) for c in nb["cells"] if c["cell_type"] == "code"]


def _python(src: str) -> str:
    """A cell's source with its magic lines blanked (line numbers kept for the error messages)."""
    return "\n".join("" if _MAGIC.match(line) else line for line in src.splitlines())


def _names(source: str) -> tuple[set[str], set[str]]:
    """``(undefined, unused imports)`` of a module source: names read that nothing in it defines,
    imports or the builtins provide, and imported names that nothing reads."""
    top = symtable.symtable(source, "<notebook>", "exec")
    defined = {s.get_name() for s in top.get_symbols() if s.is_assigned() or s.is_imported() or s.is_namespace()}
    imported = {s.get_name() for s in top.get_symbols() if s.is_imported()}
    known = defined | set(dir(builtins)) | IPYTHON_NAMES
    read: set[str] = set()
    undefined: set[str] = set()

    def walk(table, is_module: bool) -> None:
        for s in table.get_symbols():
            if not s.is_referenced():
                continue
            if is_module or s.is_global() or s.is_free():
                read.add(s.get_name())
                if (is_module or s.is_global()) and s.get_name() not in known:
                    undefined.add(s.get_name())
        for child in table.get_children():
            walk(child, False)

    walk(top, True)
    return undefined, imported - read


def test_there_are_notebooks():
    assert NOTEBOOKS, f"{NB_DIR} holds no .ipynb"


@pytest.mark.parametrize("path", NOTEBOOKS, ids=IDS)
def test_valid_nbformat_without_outputs(path):
    import nbformat

    nb = nbformat.read(path, as_version=4)
    nbformat.validate(nb)                               # raises on a malformed document
    assert nb.nbformat == 4
    assert nb.metadata.get("kernelspec", {}).get("name") == "python3", f"{path.name}: kernelspec must be python3"
    ids = [c.get("id") for c in nb.cells]
    assert len(set(ids)) == len(ids), f"{path.name}: cell ids repeat"
    for i, cell in enumerate(nb.cells):
        if cell.cell_type == "code":
            assert not cell.get("outputs"), f"{path.name} cell {i}: clear the outputs before committing"
            assert cell.get("execution_count") is None, f"{path.name} cell {i}: clear the execution count"
        assert _source(cell).strip(), f"{path.name} cell {i} is empty"


@pytest.mark.parametrize("path", NOTEBOOKS, ids=IDS)
def test_title_and_parameters_cell(path):
    nb = json.loads(path.read_text(encoding="utf-8"))
    first = nb["cells"][0]
    assert first["cell_type"] == "markdown" and _source(first).startswith("# "), \
        f"{path.name}: the first cell must be a markdown title ('# ...')"
    code = [c for c in nb["cells"] if c["cell_type"] == "code"]
    params = code[0]
    assert "parameters" in params.get("metadata", {}).get("tags", []), \
        f"{path.name}: the first code cell must be tagged 'parameters' (papermill's convention)"
    tree = ast.parse(_python(_source(params)))
    assigned = {t.id for node in ast.walk(tree) if isinstance(node, ast.Assign)
                for t in node.targets if isinstance(t, ast.Name)}
    assert {"QUICK", "OUT"} <= assigned, f"{path.name}: the parameters cell must set QUICK and OUT"
    text = _source(params)
    # the test run sets both variables: QUICK mode by default, and outputs kept out of the repository
    assert 'os.environ.get("SALAD_QUICK", "1") == "1"' in text, f"{path.name}: QUICK must default to SALAD_QUICK=1"
    assert "SALAD_NOTEBOOK_OUT" in text, f"{path.name}: OUT must come from SALAD_NOTEBOOK_OUT"
    for i, cell in enumerate(code[1:], start=1):
        assert "SALAD_QUICK" not in _source(cell), f"{path.name} code cell {i}: read SALAD_QUICK only in parameters"


@pytest.mark.parametrize("path", NOTEBOOKS, ids=IDS)
def test_code_cells_compile(path):
    for i, src in enumerate(_code_cells(path)):
        compile(_python(src), f"{path.name}:code cell {i}", "exec")   # a SyntaxError names the cell and line


@pytest.mark.parametrize("path", NOTEBOOKS, ids=IDS)
def test_no_undefined_names_or_unused_imports(path):
    undefined, unused = _names("\n".join(_python(s) for s in _code_cells(path)))
    assert not undefined, f"{path.name}: names used but never defined or imported: {sorted(undefined)}"
    assert not unused, f"{path.name}: imports never used: {sorted(unused)}"


@pytest.mark.parametrize("path", NOTEBOOKS, ids=IDS)
def test_no_machine_paths_or_hand_parsed_captions(path):
    for i, src in enumerate(_code_cells(path)):
        assert "/work/" not in src and "/home/" not in src and "/tmp/" not in src, \
            f"{path.name} code cell {i}: use repo-relative paths or OUT, not a machine's path"
        # captions come from salad_core.data.read_texts, which knows the HumanML3D line format
        assert 'split("#")' not in src, f"{path.name} code cell {i}: read captions with salad_core.data.read_texts"


def test_lint_helper_finds_what_it_should():
    undefined, unused = _names("import os\nimport numpy as np\ndef f(x):\n    return y + x\nprint([z for z in q])\n")
    assert undefined == {"y", "q"}
    assert unused == {"os", "np"}
    undefined, unused = _names("import numpy as np\nclass A:\n    v = np.zeros(2)\nf = lambda: A\n")
    assert undefined == set() and unused == set()


def test_readme_lists_every_notebook():
    readme = (NB_DIR / "README.md").read_text(encoding="utf-8")
    listed = set(re.findall(r"`(\d\d_[a-z0-9_]+)`", readme))
    assert listed == set(IDS), f"notebooks/README.md lists {sorted(listed)}; notebooks/ holds {IDS}"


@pytest.mark.skipif(shutil.which("ruff") is None, reason="ruff is not installed (the name checks above still run)")
def test_ruff_check():
    res = subprocess.run(["ruff", "check", "--select", "E9,F", "--no-cache", *map(str, NOTEBOOKS)],
                         capture_output=True, text=True)
    assert res.returncode == 0, res.stdout + res.stderr
