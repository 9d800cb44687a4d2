"""Multi-graph matching (thesis ch. 6, 7): synchronized solvers, offline synchronization, CAO;
graphs of different sizes through a universe.

Front door :func:`match_collection`; result :class:`MultiMatchingResult`. The pieces are public
for users who assemble their own pipeline: :class:`PairAffinities` (batched affinities of the
matched pairs), :func:`run_lockstep` (the lock-step solvers), :func:`cao` and the executors
:func:`map_chunks` / :func:`split_chunks`. Names load on first use.
"""

from __future__ import annotations

from .._lazy import lazy_attributes

_LAZY = {
    "PairAffinities": "._affinity",
    "CAOOutcome": "._cao",
    "cao": "._cao",
    "map_chunks": "transync.parallel",
    "split_chunks": "transync.parallel",
    "CAO_VARIANTS": "._front",
    "ONLINE_SOLVERS": "._front",
    "PARTIAL": "._front",
    "SOLVERS": "._front",
    "SYNCS": "._front",
    "match_collection": "._front",
    "LockstepOutcome": "._lockstep",
    "run_lockstep": "._lockstep",
    "MultiMatchingResult": "._result",
}

__all__ = sorted(_LAZY)


__getattr__, __dir__ = lazy_attributes(__name__, _LAZY, globals())
