"""Root pytest configuration.

* keeps modules with side effects out of doctest collection;
* ``require_dataset`` fixture and ``@pytest.mark.dataset(NAME)`` marker: tests that need a real
  data set (a sub-folder of the data home, see :func:`transync.datasets.data_home`) skip when it
  is absent or empty -- e.g. with ``TRANSYNC_DATA`` pointing at an empty folder -- instead of
  failing. A ``TRANSYNC_DATA`` that names no folder at all is still an error.
"""

from pathlib import Path

import pytest

collect_ignore = ["src/transync/__main__.py"]


def _dataset_folder(name: str) -> Path:
    """The data set folder ``name``, or skip the calling test when it is absent or empty."""
    from transync.datasets import data_home

    folder = data_home(required=False, subfolder=name)
    if folder is None or not any(folder.iterdir()):
        pytest.skip(f"real data set {name!r} not found (set TRANSYNC_DATA or place it in "
                    "../shared/data)")
    return folder


@pytest.fixture
def require_dataset():
    """``require_dataset(name) -> Path``: the data set's folder, or skip the test."""
    return _dataset_folder


def pytest_configure(config):
    config.addinivalue_line(
        "markers", "dataset(name, ...): needs these real data sets; skipped when absent")


def pytest_runtest_setup(item):
    for mark in item.iter_markers(name="dataset"):
        for name in mark.args:
            _dataset_folder(name)
