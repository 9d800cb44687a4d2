"""Loading a script of benchmarks/ as a module (they are not a package)."""

import importlib.util
from pathlib import Path

import pytest

BENCHMARKS = Path(__file__).resolve().parents[2] / "benchmarks"


def _load(name: str, module_name: str):
    """``benchmarks/<name>.py`` executed as a module called ``module_name``."""
    spec = importlib.util.spec_from_file_location(module_name, BENCHMARKS / f"{name}.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


@pytest.fixture(scope="session")
def load_benchmark():
    """The loader: ``load_benchmark(name, module_name)``."""
    return _load
