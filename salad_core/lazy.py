"""Packages whose names are imported on first use: importing the package itself loads no torch.

``salad_core.bench`` and ``salad_core.train`` export many names from their modules; the ``python -m``
entry points tune the process (threads, allocator) before torch is loaded, so those packages resolve their
exports lazily through :func:`lazy_exports`.
"""
from __future__ import annotations

import importlib
from typing import Any, Callable, Mapping

__all__ = ["lazy_exports"]


def lazy_exports(package: str, exports: Mapping[str, str],
                 namespace: dict[str, Any]) -> tuple[Callable[[str], Any], Callable[[], list[str]]]:
    """The module-level ``__getattr__`` and ``__dir__`` of ``package``: a name of ``exports`` (name -> the
    package's module that defines it) is imported from ``package.module`` on first access and kept in
    ``namespace`` (the package's ``globals()``); any other name raises ``AttributeError``."""

    def __getattr__(name: str) -> Any:
        module = exports.get(name)
        if module is None:
            raise AttributeError(f"module {package!r} has no attribute {name!r}")
        value = getattr(importlib.import_module(f"{package}.{module}"), name)
        namespace[name] = value
        return value

    def __dir__() -> list[str]:
        return sorted(set(namespace) | set(exports))

    return __getattr__, __dir__
