"""The reference documentation (docs/): complete API pages, and a clean build.

The build tests run ``sphinx-build -W --keep-going`` on a copy of ``docs/`` (the configuration
is read from the repository, so nothing is written into the working tree), with the gallery
running the ``plot_*`` examples: the ``dummy`` builder in CI (every page read, every docstring
parsed, no output written), the ``html`` one marked slow. They are skipped when the docs packages
(the ``docs`` extra, also part of ``test``) are not installed.
"""

from __future__ import annotations

import importlib
import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
DOCS = REPO / "docs"
EXAMPLES = REPO / "examples"
DOCS_PACKAGES = ("sphinx", "numpydoc", "sphinx_gallery", "myst_parser", "pydata_sphinx_theme")

#: every public package with an API page of its own
PACKAGES = ("permutations", "geometry", "graphs", "metrics", "parallel", "matching",
            "synchronization", "multigraph", "kernels", "homography", "datasets", "experiments",
            "exceptions")


def _listed_names(page: Path) -> set[str]:
    """Names an API page documents: autosummary entries and re-export references."""
    text = page.read_text(encoding="utf-8")
    names = set()
    for block in re.findall(r"\.\. autosummary::\n(?:   :.*\n)*\n((?:   \S.*\n)+)", text):
        names.update(line.strip() for line in block.splitlines())
    names.update(re.findall(r":\w+:`(\w+) <[\w.]+>`", text))
    return names


@pytest.mark.parametrize("package", PACKAGES)
def test_api_page_lists_every_public_name(package):
    module = importlib.import_module(f"transync.{package}")
    public = {name for name in module.__all__
              if not name.startswith("__") and not hasattr(getattr(module, name), "__path__")}
    listed = _listed_names(DOCS / "api" / f"transync.{package}.rst")
    assert public - listed == set(), f"missing from docs/api/transync.{package}.rst"
    assert listed - public == set(), f"not public in transync.{package}"


def test_top_level_page_lists_every_name():
    import transync

    text = (DOCS / "api" / "transync.rst").read_text(encoding="utf-8")
    listed = set(re.findall(r"``transync\.(\w+)``", text))
    assert set(transync.__all__) - {"__version__"} == listed - {"__version__"}


def test_every_api_page_is_in_the_index():
    index = (DOCS / "api" / "index.rst").read_text(encoding="utf-8")
    pages = {p.stem for p in (DOCS / "api").glob("transync*.rst")}
    assert pages == set(re.findall(r"^   (transync[\w.]*)$", index, flags=re.M))


def test_examples_take_an_output_folder():
    """No example writes into the working directory: each saving one takes a folder argument."""
    for script in EXAMPLES.glob("*.py"):
        text = script.read_text(encoding="utf-8")
        assert text.startswith('"""\n'), f"{script.name}: sphinx-gallery needs a titled docstring"
        if "savefig" in text or ".write_" in text:
            assert "sys.argv[1]" in text and "tempfile" in text, script.name


def _build(tmp_path: Path, builder: str) -> Path:
    """``sphinx-build -W --keep-going -b builder`` of a copy of docs/; returns the output folder.

    The gallery runs the ``plot_*`` examples; the checks afterwards make sure that they wrote
    nothing next to themselves or into the repository.
    """
    for name in DOCS_PACKAGES:
        pytest.importorskip(name)
    source = tmp_path / "src"
    shutil.copytree(DOCS, source, ignore=shutil.ignore_patterns(
        "_build", "auto_examples", "generated", "sg_execution_times.rst", "__pycache__"))
    examples_before = sorted(p.name for p in EXAMPLES.iterdir())
    root_before = sorted(p.name for p in REPO.iterdir())
    env = {**os.environ, "MPLBACKEND": "Agg", "TRANSYNC_DOCS_GALLERY": "1"}
    out = tmp_path / builder
    proc = subprocess.run(
        [sys.executable, "-m", "sphinx", "-W", "--keep-going", "-q", "-b", builder,
         "-c", str(DOCS), "-d", str(tmp_path / "doctrees"), str(source), str(out)],
        capture_output=True, text=True, env=env, cwd=tmp_path, timeout=900)
    assert proc.returncode == 0, proc.stderr[-5000:]
    assert "WARNING" not in proc.stderr, proc.stderr[-5000:]
    # every public name got its generated page, and the gallery ran
    assert (source / "api" / "generated" / "transync.matching.match_graphs.rst").is_file()
    assert (source / "auto_examples" / "plot_pairwise_matching.rst").is_file()
    assert sorted(p.name for p in EXAMPLES.iterdir()) == examples_before
    assert sorted(p.name for p in REPO.iterdir()) == root_before
    return out


def test_docs_build_without_warnings(tmp_path):
    """Every page is read, every docstring parsed, every plot_ example run: no warning.

    The ``dummy`` builder does all of that but writes no output (about 30 s of CPU; the html
    build below adds about 15 s and is marked slow).
    """
    _build(tmp_path, "dummy")


def test_cli_directive_renders_every_subcommand():
    pytest.importorskip("sphinx")
    sys.path.insert(0, str(DOCS / "_ext"))
    try:
        from transync_cli import _subcommands
    finally:
        sys.path.remove(str(DOCS / "_ext"))
    from transync.cli import build_parser

    parser = build_parser()
    names = [name for name, _, _ in _subcommands(parser)]
    choices = next(a for a in parser._actions if isinstance(getattr(a, "choices", None), dict))
    assert names == list(choices.choices)
    assert all(summary for _, summary, _ in _subcommands(parser))


@pytest.mark.slow
def test_docs_build_html(tmp_path):
    html = _build(tmp_path, "html")
    for page in ("index.html", "cli.html", "methods/kernels.html", "notes.html",
                 "api/generated/transync.matching.match_graphs.html",
                 "experiments/multigraph/README.html"):
        assert (html / page).is_file(), page
    cli = (html / "cli.html").read_text(encoding="utf-8")
    from transync.cli import build_parser

    commands = next(a for a in build_parser()._actions
                    if isinstance(getattr(a, "choices", None), dict)).choices
    for command in commands:
        assert f"transync {command}" in cli, command
    gallery = (html / "auto_examples" / "plot_pairwise_matching.html").read_text(encoding="utf-8")
    assert "sphx_glr_plot_pairwise_matching_001.png" in gallery     # the figure was rendered
