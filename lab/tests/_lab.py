"""Where the lab's files are, for its tests: the repository, the lab, its scripts (grouped by question) and records."""
from __future__ import annotations

import importlib.util
import sys
from pathlib import Path
from types import ModuleType

LAB = Path(__file__).resolve().parents[1]
REPO = LAB.parent
SCRIPTS = LAB / "scripts"
RECORDS = LAB / "records"
CONFIGS = LAB / "configs"
#: the kept ablation study (groups.json and the probe records; its models and evaluations are the shipped ones)
STUDY = RECORDS / "ablations_v2"
#: the shipped ablation study (models, evaluations, index, readings)
SHIPPED = REPO / "salad_core" / "weights" / "ablations"


def script_path(name: str) -> Path:
    """``lab/scripts/<question>/<name>`` (``name`` with its suffix; ``.py`` when it has none)."""
    name = name if "." in name else f"{name}.py"
    found = sorted(SCRIPTS.glob(f"*/{name}")) + sorted(SCRIPTS.glob(name))
    if len(found) != 1:
        raise FileNotFoundError(f"{name}: {len(found)} scripts of that name under {SCRIPTS}")
    return found[0]


def script_command(name: str) -> str:
    """The script's path relative to the repository, as commands name it (``lab/scripts/<question>/<name>``)."""
    return script_path(name).relative_to(REPO).as_posix()


def load_script(name: str) -> ModuleType:
    """A lab script as a module, imported as ``python lab/scripts/<question>/<name>.py`` runs it: with its folder
    on ``sys.path`` while it loads, for its sibling helpers (``_measure_common``)."""
    path = script_path(name)
    spec = importlib.util.spec_from_file_location(path.stem, path)
    module = importlib.util.module_from_spec(spec)
    sys.path.insert(0, str(path.parent))
    try:
        spec.loader.exec_module(module)
    finally:
        sys.path.remove(str(path.parent))
    return module
