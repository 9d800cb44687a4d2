"""Exceptions and warnings raised by transync."""

from __future__ import annotations

__all__ = [
    "ConvergenceWarning",
    "DegenerateInputError",
    "ExecutorError",
    "ExperimentStoreError",
    "TransyncError",
    "UnlinkedViewsWarning",
]


class TransyncError(Exception):
    """Base class of the errors transync raises besides ``ValueError``/``TypeError``.

    Examples
    --------
    >>> from transync.exceptions import DegenerateInputError, TransyncError
    >>> issubclass(DegenerateInputError, TransyncError)
    True
    """


class DegenerateInputError(TransyncError, ValueError):
    """Input is well formed but degenerate (singular maps, disconnected observations, ...).

    A ``ValueError``, so ``except ValueError`` catches it too.

    Examples
    --------
    >>> import numpy as np
    >>> from transync.synchronization import synchronize_linear_maps
    >>> T = {(0, 1): np.eye(2), (2, 3): np.eye(2)}           # two separate components
    >>> try:
    ...     synchronize_linear_maps(T)
    ... except DegenerateInputError as exc:
    ...     print(type(exc).__name__)
    DegenerateInputError
    """


class ConvergenceWarning(UserWarning):
    """An iterative method stopped at its iteration limit before meeting its tolerance.

    The result is still returned, with ``converged=False``.

    Examples
    --------
    >>> import warnings
    >>> import numpy as np
    >>> from transync.matching import sm
    >>> K = np.ones((4, 4)) + np.eye(4)
    >>> with warnings.catch_warnings(record=True) as caught:
    ...     warnings.simplefilter("always")
    ...     res = sm(K, n1=2, n2=2, max_iter=1, tol=1e-12)
    >>> res.converged, caught[0].category.__name__
    (False, 'ConvergenceWarning')
    """


class ExecutorError(TransyncError, RuntimeError):
    """An executor could not run the work: dead or unreachable scheduler, lost worker, timeout.

    Raised instead of hanging. An exception raised by the work itself is not wrapped: it keeps
    its type (with a note naming the chunk it came from).

    Examples
    --------
    >>> issubclass(ExecutorError, RuntimeError)
    True
    """


class ExperimentStoreError(TransyncError):
    """An experiment's result store cannot be used (corrupted, locked by another run,
    unwritable).

    Examples
    --------
    >>> import pathlib, tempfile
    >>> from transync.experiments import ExperimentStore
    >>> bad = pathlib.Path(tempfile.mkdtemp()) / "results.sqlite"
    >>> _ = bad.write_bytes(b"not a database" * 100)
    >>> try:
    ...     ExperimentStore(bad)
    ... except ExperimentStoreError:
    ...     print("refused")
    refused
    """


class UnlinkedViewsWarning(UserWarning):
    """Some views could not be linked to the reference; their estimates are missing (NaN).

    Examples
    --------
    >>> issubclass(UnlinkedViewsWarning, UserWarning)
    True
    """
