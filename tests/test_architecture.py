"""The layering of the design: a layer imports only layers below it, and only their public names.

The layers, lowest first (DESIGN.md, "Layers"; ``kernels`` sits above ``multigraph`` because the
transitive kernel runs its pairwise work on the lock-step solvers and executors of
``match_collection``, as its issue's "builds on" says). The core modules (validation, BLAS
threads, lazy imports, progress bars, the allocator, exceptions, plane geometry, executors) are
shared by every layer. Every import in ``src/transync`` is read from the source, function-level
imports included, so a lazy import cannot hide a cycle.
"""
from __future__ import annotations

import ast
from pathlib import Path

import pytest

SRC = Path(__file__).resolve().parents[1] / "src" / "transync"

CORE = frozenset({"exceptions", "_validation", "_blas", "_lazy", "_progress", "_malloc",
                  "geometry", "parallel"})

#: rank of every layer; a module may import its own layer, the core and lower ranks only
RANK = {
    "permutations": 1, "graphs": 1,
    "metrics": 2,
    "datasets": 3, "matching": 3,
    "synchronization": 4,
    "homography": 5, "multigraph": 5,
    "kernels": 6,
    "experiments": 7,
    "cli": 8,
    "__init__": 9, "__main__": 9,
}
#: imports the core itself may make (it is below every layer)
CORE_ALLOWED = {"parallel": {"_malloc", "_progress", "_validation", "exceptions"},
                "geometry": {"_validation"}, "_validation": {"exceptions"}}


def _layer(parts: list[str]) -> str:
    """The layer of a module path below ``transync`` (``["multigraph", "_front"]``)."""
    return parts[0] if parts else "__init__"


def imports_of(source: str, module: list[str],
               is_package: bool) -> list[tuple[list[str], list[str]]]:
    """(target module path below ``transync``, imported names) of every transync import."""
    package = module if is_package else module[:-1]
    found = []
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.ImportFrom):
            if node.level:
                base = package[:len(package) - (node.level - 1)]
                target = base + (node.module.split(".") if node.module else [])
            elif node.module and node.module.split(".")[0] == "transync":
                target = node.module.split(".")[1:]
            else:
                continue
            names = [a.name for a in node.names]
            if not node.module:            # "from .. import kernels": the names are modules,
                # except the package's metadata ("from .. import __version__")
                found.extend((target + [n], []) if not n.startswith("__") else (target, [n])
                             for n in names)
            else:
                found.append((target, names))
        elif isinstance(node, ast.Import):
            for a in node.names:
                parts = a.name.split(".")
                if parts[0] == "transync":
                    found.append((parts[1:], []))
    return found


def violations(source: str, module: list[str], is_package: bool = False) -> list[str]:
    """What an import of ``module`` (path below ``transync``) breaks, one line per import."""
    src = _layer(module)
    out = []
    for target, names in imports_of(source, module, is_package):
        dst = _layer(target)
        where = f"{'.'.join(module)} imports {'.'.join(target) or 'transync'}"
        if dst == src or (not target and all(n.startswith("__") for n in names)):
            continue
        if src in CORE:
            if dst not in CORE_ALLOWED.get(src, set()):
                out.append(f"{where}: the core module {src!r} may not import {dst!r}")
            continue
        if dst not in CORE and dst not in RANK:
            out.append(f"{where}: unknown layer {dst!r}")
            continue
        if dst not in CORE and RANK[dst] >= RANK[src]:
            out.append(f"{where}: layer {src!r} may import only layers below it, not {dst!r}")
        if dst not in CORE:
            private = [p for p in target[1:] if p.startswith("_") and not p.startswith("__")]
            private += [n for n in names if n.startswith("_") and not n.startswith("__")]
            if private:
                out.append(f"{where}: private names of another layer {private}")
    return out


def _modules():
    for path in sorted(SRC.rglob("*.py")):
        parts = list(path.relative_to(SRC).with_suffix("").parts)
        is_package = parts[-1] == "__init__"
        if is_package:
            parts = parts[:-1]
        yield path, parts, is_package


def test_every_layer_is_known():
    layers = {_layer(parts) for _, parts, _ in _modules()}
    assert layers <= set(RANK) | CORE, layers - set(RANK) - CORE


def test_layers_import_only_downward_and_only_public_names():
    found = []
    for path, parts, is_package in _modules():
        found += violations(path.read_text(encoding="utf-8"), parts, is_package)
    assert not found, "\n".join(found)


@pytest.mark.parametrize("source, module, expected", [
    ("from ..multigraph import match_collection", ["matching", "_rrwm"],
     "may import only layers below"),
    ("from ..synchronization._birkhoff import sweep", ["multigraph", "_front"],
     "private names"),
    ("from ..synchronization import _blocks", ["multigraph", "_front"], "private names"),
    ("def f():\n    from transync.cli import main", ["kernels", "_hks"],
     "may import only layers below"),
    ("import transync.experiments", ["homography", "_dense"], "may import only layers below"),
    ("from . import multigraph", ["geometry"], "the core module"),
    ("from .. import kernels as kx", ["multigraph", "_front"], "may import only layers below"),
])
def test_the_checker_catches(source, module, expected):
    found = violations(source, module)
    assert len(found) == 1 and expected in found[0], found


@pytest.mark.parametrize("source, module", [
    ("from ..synchronization import synchronize_permutations", ["multigraph", "_front"]),
    ("from .._validation import check_array", ["kernels", "_hks"]),
    ("from ._birkhoff import sweep", ["synchronization", "_front"]),
    ("from .. import matching", ["multigraph", "_front"]),
    ("from .. import __version__", ["cli"]),
])
def test_the_checker_allows(source, module):
    assert violations(source, module, is_package=module == ["cli"]) == []
