"""Sphinx configuration of the transync reference documentation.

Build: ``sphinx-build -W --keep-going -b html docs docs/_build/html`` (or ``make -C docs html``).
Everything is local: no intersphinx, no download. The gallery runs the examples whose file name
starts with ``plot_`` (set ``TRANSYNC_DOCS_GALLERY=0`` to show them without running them).
"""

from __future__ import annotations

import os
import sys
from pathlib import Path

DOCS = Path(__file__).resolve().parent
REPO = DOCS.parent
sys.path.insert(0, str(DOCS / "_ext"))
if (REPO / "src" / "transync").is_dir():    # an uninstalled checkout
    sys.path.insert(0, str(REPO / "src"))

import transync  # noqa: E402

project = "transync"
author = "transync developers"
copyright = "transync developers"
release = version = transync.__version__

extensions = [
    "sphinx.ext.autodoc",
    "sphinx.ext.autosummary",
    "sphinx.ext.mathjax",
    "numpydoc",
    "myst_parser",
    "sphinx_gallery.gen_gallery",
    "transync_cli",
]

source_suffix = {".rst": "restructuredtext", ".md": "markdown"}
root_doc = "index"
templates_path = ["_templates"]
exclude_patterns = ["_build", "**/.ipynb_checkpoints", "auto_examples/*.ipynb",
                    "auto_examples/*.py", "auto_examples/*.zip", "auto_examples/*.json",
                    "auto_examples/*.md5", "sg_execution_times.rst"]
# the experiments' tables are included from their README pages, not pages of their own
exclude_patterns += ["experiments/*/summary.md", "experiments/*/table_*.md",
                     "experiments/*/tables_*.md", "experiments/*/psd.md",
                     "experiments/*/rerun_*.md"]

# -- autodoc / autosummary / numpydoc -------------------------------------------------------
autosummary_generate = True
autosummary_imported_members = True
autodoc_typehints = "none"             # numpydoc's Parameters sections carry the types
autodoc_default_options = {"members": False}
numpydoc_show_class_members = False
numpydoc_class_members_toctree = False
numpydoc_attributes_as_param_list = False
numpydoc_xref_param_type = False

# -- MyST (the Markdown pages: design notes and experiment reports) ------------------------------
myst_enable_extensions = ["dollarmath", "amsmath", "deflist"]
myst_heading_anchors = 3

# -- sphinx-gallery over examples/ ---------------------------------------------------------------
_run_gallery = os.environ.get("TRANSYNC_DOCS_GALLERY", "1") != "0"
sphinx_gallery_conf = {
    "examples_dirs": str(REPO / "examples"),
    "gallery_dirs": "auto_examples",
    "filename_pattern": r"/plot_",
    "plot_gallery": "True" if _run_gallery else "False",
    "download_all_examples": False,
    "remove_config_comments": True,
    "matplotlib_animations": False,
    "reference_url": {"transync": None},
    "within_subsection_order": "FileNameSortKey",
}

# -- constants: their ``#:`` comment in the module that defines them, never their type's docstring


def _defining_modules(modname: str):
    """``modname`` and its private submodules (where re-exported constants are assigned)."""
    import importlib
    import pkgutil

    yield modname
    module = importlib.import_module(modname)
    for info in pkgutil.iter_modules(getattr(module, "__path__", [])):
        yield f"{modname}.{info.name}"


def _constant_docstring(app, what, name, obj, options, lines):
    if what != "data":
        return
    from sphinx.pycode import ModuleAnalyzer, PycodeError

    modname, attr = name.rsplit(".", 1)
    for candidate in _defining_modules(modname):
        try:
            docs = ModuleAnalyzer.for_module(candidate).find_attr_docs()
        except PycodeError:
            continue
        if ("", attr) in docs:
            lines[:] = [line for line in docs[("", attr)] if line is not None]
            return
    lines[:] = []


def setup(app):
    app.connect("autodoc-process-docstring", _constant_docstring)


# -- HTML ---------------------------------------------------------------------------------------
html_theme = "pydata_sphinx_theme"
html_title = f"transync {version}"
html_theme_options = {
    "navigation_with_keys": False,
    "show_toc_level": 2,
    "secondary_sidebar_items": ["page-toc"],
}
html_static_path: list[str] = []
html_show_sourcelink = False
