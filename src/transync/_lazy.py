"""Names of a package imported on first use (private; one home for every package ``__init__``).

Heavy dependencies (SciPy's sparse solvers, scikit-learn, OpenCV, matplotlib) are imported only
by the modules that use them; a package ``__init__`` lists its public names with the module that
defines each, and :func:`lazy_attributes` builds the module-level ``__getattr__`` (PEP 562) and
``__dir__`` that import it when the name is first read.
"""

from __future__ import annotations

import importlib
from collections.abc import Callable, Mapping

__all__ = ["lazy_attributes"]


def lazy_attributes(package: str, table: Mapping[str, str | tuple[str, str | None]],
                    namespace: dict) -> tuple[Callable[[str], object], Callable[[], list]]:
    """``(__getattr__, __dir__)`` for ``package`` whose names in ``table`` import lazily.

    Parameters
    ----------
    package : str
        The package's ``__name__`` (anchor of relative module names, and named in errors).
    table : mapping
        ``name -> module`` (the attribute of that name in the module, relative names allowed)
        or ``name -> (module, attribute)``, with attribute ``None`` for the module itself.
    namespace : dict
        The package's ``globals()``: a name read once is stored there, so the next read is a
        plain lookup.

    Returns
    -------
    (callable, callable)
        The package's ``__getattr__`` and ``__dir__``.

    Examples
    --------
    >>> ns = {}
    >>> getattr_, dir_ = lazy_attributes("transync", {"sqrt": ("math", "sqrt"),
    ...                                               "json": ("json", None)}, ns)
    >>> getattr_("sqrt")(9.0), getattr_("json").__name__, sorted(ns), dir_()
    (3.0, 'json', ['json', 'sqrt'], ['json', 'sqrt'])
    >>> getattr_("nope")
    Traceback (most recent call last):
    ...
    AttributeError: module 'transync' has no attribute 'nope'
    """

    def __getattr__(name: str):
        try:
            entry = table[name]
        except KeyError:
            raise AttributeError(f"module {package!r} has no attribute {name!r}") from None
        module, attr = (entry, name) if isinstance(entry, str) else entry
        mod = importlib.import_module(module, package)
        value = mod if attr is None else getattr(mod, attr)
        namespace[name] = value
        return value

    def __dir__():
        return sorted(set(namespace) | set(table))

    return __getattr__, __dir__
