"""The step-wise protocol shared by the iterative QAP solvers.

Synchronized multi-graph solvers (S-GA, S-RRW, S-PF) run one pairwise solver per graph pair and,
between two outer steps, replace each pair's relaxed iterate by a cycle-consistent one. Each
iterative solver therefore exists as a *stepper* object that exposes its state:

>>> import numpy as np
>>> from transync.graphs import Graph
>>> from transync.matching import RRWMStepper, gaussian_edge_affinity
>>> rng = np.random.default_rng(0)
>>> g1 = Graph.from_points(rng.random((6, 2)), edges="full")
>>> g2 = g1.permute(rng.permutation(6))
>>> st = RRWMStepper(gaussian_edge_affinity(g1, g2))
>>> while not st.done:
...     X = st.iterate                 # (n1, n2) doubly-stochastic iterate
...     st.set_iterate(X)              # a synchronizer would overwrite it here
...     _ = st.step()
>>> res = st.result()
>>> bool(np.all(g2.points[res.assignment] == g1.points))
True

The public functions (:func:`~transync.matching.rrwm` etc.) are a thin loop over the stepper:
``while not st.done: st.step()``, then a ``ConvergenceWarning`` if ``st.converged`` is false, then
``st.result()``.
"""

from __future__ import annotations

import warnings
from typing import Protocol, runtime_checkable

import numpy as np

from .._blas import blas_limit
from .._validation import check_affinity_scale, check_array, check_nonnegative
from ..exceptions import ConvergenceWarning
from ..geometry import rescale_homogeneous
from ..permutations import assignment_to_matrix, solve_lap
from ._affinity import Affinity, SeparableAffinity
from ._result import MatchingResult

__all__ = ["Stepper"]


@runtime_checkable
class Stepper(Protocol):
    """Step-wise interface of an iterative pairwise QAP solver.

    Attributes
    ----------
    affinity : Affinity
        The problem (the caller's affinity; solvers may keep a normalized copy internally).
    n_iter : int
        Outer steps performed so far.
    converged : bool
        Whether the solver's stopping criterion has been met.
    done : bool
        ``converged`` or the iteration budget is spent; ``step`` does nothing once done.

    Methods
    -------
    iterate
        Property: the current relaxed solution, an ``(n1, n2)`` array. For RRWM it is the Sinkhorn
        output, for GA the per-beta matrix (both (sub-)doubly stochastic), for PF the Frank-Wolfe
        iterate in the (rectangular) Birkhoff polytope, for IPFP the continuous iterate, for SM the
        leading eigenvector estimate (unit norm, not doubly stochastic).
    step()
        One outer iteration (RRWM, SM, IPFP: one iteration; GA: one beta level, with its inner loop
        run to convergence; PF: one lambda step). Returns ``done``.
    set_iterate(X)
        Overwrite the relaxed state with ``X`` (e.g. a synchronized matrix; non-negative, with
        entries in [0, 1] for GA, PF and IPFP, whose iterates are points of the Birkhoff
        polytope) and continue from it; resets ``converged`` so that at least one more step is
        taken.
    result()
        Round the current state with the Hungarian algorithm and return a :class:`MatchingResult`.

    Examples
    --------
    Every solver's stepper follows this protocol; driving one by hand:

    >>> import numpy as np
    >>> from transync.matching import RRWMStepper
    >>> K = np.ones((4, 4)) + 3 * np.eye(4)
    >>> K[1, 2] = K[2, 1] = 0.0
    >>> s = RRWMStepper(K, n1=2, n2=2)
    >>> s.step(), s.n_iter, s.iterate.shape
    (False, 1, (2, 2))
    >>> s.set_iterate(np.full((2, 2), 0.5))            # e.g. a synchronized matrix
    >>> while not s.step():
    ...     pass
    >>> s.result().assignment
    array([0, 1])
    """

    affinity: Affinity
    n_iter: int
    converged: bool

    @property
    def iterate(self) -> np.ndarray: ...

    @property
    def done(self) -> bool: ...

    def step(self) -> bool: ...

    def set_iterate(self, X) -> None: ...

    def result(self) -> MatchingResult: ...


class _BaseStepper:
    """Bookkeeping shared by the steppers: budget, convergence flag, rounding."""

    method = ""
    unit_iterate = False        # the iterate lives in [0, 1] (GA, PF, IPFP): set_iterate checks

    def __init__(self, affinity: Affinity, *, max_iter: int):
        self.affinity = affinity
        self.n1, self.n2 = affinity.n1, affinity.n2
        self.max_iter = max_iter
        self.n_iter = 0
        self.converged = False
        self._X = np.full((self.n1, self.n2), 1.0 / max(self.n1, self.n2))

    @property
    def done(self) -> bool:
        return self.converged or self.n_iter >= self.max_iter

    @property
    def iterate(self) -> np.ndarray:
        return self._X.copy()

    def _check_iterate(self, X, name: str = "X") -> np.ndarray:
        X = check_array(X, name, ndim=2)
        if X.shape != (self.n1, self.n2):
            raise ValueError(f"`{name}` must have shape ({self.n1}, {self.n2}), got {X.shape}")
        check_nonnegative(X, name)
        if self.unit_iterate and X.size and X.max() > 1.0 + 1e-6:
            # a point of the (sub-)Birkhoff polytope has entries in [0, 1]; IPFP's products
            # overflowed at 1e200 * I (RRWM and SM rescale their iterate: any scale will do)
            raise ValueError(f"`{name}` must have entries in [0, 1] ({self.method}'s iterate is a "
                             f"relaxed assignment), got maximum {float(X.max()):.6g}")
        if not self.unit_iterate:
            # RRWM and SM rescale their iterate, so any scale will do; a huge or tiny one is
            # brought to a largest entry in [0.5, 1) by a power of two (exact; entries within
            # [2**-100, 2**100] stay as given): at 1e200 SM's ||K x|| overflowed and its iterate
            # became 0, at 1e-200 it underflowed; RRWM's sum overflowed at 1.7e308
            return rescale_homogeneous(X)
        return np.array(X, dtype=float)

    def set_iterate(self, X) -> None:
        self._X = self._check_iterate(X)
        self.converged = False

    def step(self) -> bool:  # pragma: no cover - overridden
        raise NotImplementedError

    def _rounding_scores(self) -> np.ndarray:
        return self._X

    def _info(self) -> dict:
        return {}

    def result(self) -> MatchingResult:
        assignment = solve_lap(self._rounding_scores())
        objective = self.affinity.score(assignment_to_matrix(assignment, self.n2))
        return MatchingResult(assignment=assignment, soft=self._X.copy(), objective=objective,
                              n_iter=self.n_iter, converged=bool(self.converged),
                              method=self.method, n2=self.n2, info=self._info())


# Below this many candidate pairs (n1 * n2) the solvers' matrix products are small: BLAS threads
# buy little, and on a busy machine (or under the experiment runner's worker processes) their
# spin-waiting makes each product up to 20x slower. Such loops run single-threaded.
def _run(stepper) -> MatchingResult:
    """Thin loop of the public functions: step until done, warn if not converged."""
    with blas_limit(stepper.n1 * stepper.n2):
        while not stepper.done:
            stepper.step()
    if not stepper.converged:
        warnings.warn(f"{stepper.method}: stopped at max_iter={stepper.max_iter} before meeting "
                      "the tolerance; the result may be poor (raise `max_iter` or `tol`)",
                      ConvergenceWarning, stacklevel=3)
    return stepper.result()


class _SymmetrizedAffinity(Affinity):
    """``(K + K^T) / 2`` through products; same quadratic form as ``K``."""

    def __init__(self, base: Affinity):
        self.base = base
        self.n1, self.n2 = base.n1, base.n2

    def matvec(self, X):
        return 0.5 * (self.base.matvec(X) + self.base.rmatvec(X))

    def diag(self):
        return self.base.diag()

    def to_dense(self):
        K = self.base.to_dense()
        return 0.5 * (K + K.T)


class _ScaledAffinity(Affinity):
    """``factor * K`` through products (solvers invariant to the scale of ``K``)."""

    def __init__(self, base: Affinity, factor: float):
        self.base, self.factor = base, factor
        self.n1, self.n2 = base.n1, base.n2

    def matvec(self, X):
        return self.factor * self.base.matvec(X)

    def rmatvec(self, X):
        return self.factor * self.base.rmatvec(X)

    def diag(self):
        return self.factor * self.base.diag()

    def to_dense(self):
        return self.factor * self.base.to_dense()


def _moderate(affinity: Affinity, *, limit: float = 1e100) -> Affinity:
    """``affinity`` itself, or rescaled to a largest column sum of 1 when that sum lies outside
    ``[1 / limit, limit]`` (products of a 1e200 ``K`` overflow in norms and dot products).

    For the solvers that rank matchings by ``vec(X)^T K vec(X)``, which a positive factor does not
    change; ordinary affinities are returned untouched, so their arithmetic is unchanged.
    """
    with np.errstate(over="ignore"):
        top = affinity.max_column_sum()
    check_affinity_scale(top)
    if top == 0 or 1.0 / limit <= top <= limit:
        return affinity
    if np.isfinite(top):
        return _ScaledAffinity(affinity, 1.0 / top)
    # the sum itself overflowed: sum the entries times 1e-200 instead
    tiny = float(affinity.rmatvec(np.full((affinity.n1, affinity.n2), 1e-200)).max())
    return _ScaledAffinity(affinity, 1e-200 / tiny)


def _symmetric(affinity: Affinity, *, rtol: float = 1e-10) -> Affinity:
    """``affinity`` itself if it is symmetric (checked on one random probe, or on the factors of
    a separable expansion: symmetric factors give a symmetric K), else its symmetric part."""
    if isinstance(affinity, SeparableAffinity) and affinity.symmetric:
        return affinity           # undirected graphs: no two products (20 % of sm at n = 100)
    probe = np.random.default_rng(12345).random((affinity.n1, affinity.n2))
    a, b = affinity.matvec(probe), affinity.rmatvec(probe)
    scale = max(float(np.abs(a).max(initial=0.0)), 1e-300)
    if float(np.abs(a - b).max(initial=0.0)) <= rtol * scale:
        return affinity
    return _SymmetrizedAffinity(affinity)


def _power_iteration(matvec, n1: int, n2: int, *, max_iter: int, tol: float):
    """Leading eigenpair of a non-negative symmetric operator from a uniform start."""
    v = np.full((n1, n2), 1.0 / np.sqrt(n1 * n2))
    lam = 0.0
    for it in range(1, max_iter + 1):
        w = matvec(v)
        lam = float(np.vdot(v, w))
        nrm = np.linalg.norm(w)
        if nrm == 0:
            return 0.0, v, it, True
        w /= nrm
        if np.linalg.norm(w - v) < tol:
            return lam, w, it, True
        v = w
    return lam, v, max_iter, False
