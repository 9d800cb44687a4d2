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
    """Base class of the errors transync raises besides ``ValueError``/``TypeError``."""


class DegenerateInputError(TransyncError, ValueError):
    """Input is well formed but degenerate (singular maps, disconnected observations, ...)."""


class ConvergenceWarning(UserWarning):
    """An iterative method stopped at its iteration limit before meeting its tolerance."""


class ExecutorError(TransyncError, RuntimeError):
    """An executor could not run the work: dead or unreachable scheduler, lost worker, timeout.

    Raised instead of hanging. An exception raised by the work itself is not wrapped: it keeps
    its type (with a note naming the chunk it came from).
    """


class ExperimentStoreError(TransyncError):
    """An experiment's result store cannot be used (corrupted, locked by another run, unwritable)."""


class UnlinkedViewsWarning(UserWarning):
    """Some views could not be linked to the reference; their estimates are missing (NaN)."""
