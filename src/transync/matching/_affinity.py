"""Affinities for quadratic graph matching, behind one small interface.

A Lawler QAP maximizes ``vec(X)^T K vec(X)`` over matchings ``X`` of shape ``(n1, n2)``. The
solvers never see ``K``; they call :meth:`Affinity.matvec`, which returns ``reshape(K vec(X))``
as an ``(n1, n2)`` array. ``vec`` is column-major, as in pygmtools: candidate ``(i, a)`` has index
``a * n1 + i``.

Backends
--------
``DenseAffinity``       a dense ``K`` handed in by the caller (pygmtools layout);
``SparseAffinity``      a ``scipy.sparse`` ``K``;
``FactorizedAffinity``  node term ``(n1, n2)`` plus an edge-pair term ``(m1, m2)`` over directed
                        edge lists; a product costs ``O(m1 m2 + n1 n2)`` and nothing of size
                        ``(n1 n2)^2`` is ever formed (Zhou & De la Torre's factorization);
``SeparableAffinity``   for fully connected (or any) graphs with a scalar edge attribute and a
                        Gaussian kernel: ``k(x, y) ~= sum_r f_r(x) g_r(y)`` so that
                        ``K ~= diag(node) + sum_r F_r (x) G_r`` and a product costs
                        ``O(R (n1^2 n2 + n1 n2^2))``. The rank ``R`` is chosen for a requested
                        accuracy and the achieved entrywise error is reported (``max_error``).

Examples
--------
>>> import numpy as np
>>> from transync.graphs import Graph
>>> from transync.matching import gaussian_edge_affinity
>>> rng = np.random.default_rng(0)
>>> g1 = Graph.from_points(rng.random((6, 2)), edges="full")
>>> g2 = g1.permute(rng.permutation(6))
>>> fast = gaussian_edge_affinity(g1, g2, sigma2=0.15)            # separable or factorized
>>> dense = gaussian_edge_affinity(g1, g2, sigma2=0.15, backend="dense")
>>> X = rng.random((6, 6))
>>> bool(np.allclose(fast.matvec(X), dense.matvec(X), atol=1e-8))
True
"""

from __future__ import annotations

from abc import ABC, abstractmethod

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from .._blas import blas_limit
from .._validation import (
    check_affinity_magnitude,
    check_array,
    check_choice,
    check_index_pairs,
    check_int,
    check_int_array,
    check_nonnegative,
    check_positive,
)
from ..exceptions import DegenerateInputError
from ..graphs import Graph

__all__ = [
    "DEFAULT_SIGMA2",
    "Affinity",
    "DenseAffinity",
    "FactorizedAffinity",
    "SeparableAffinity",
    "SparseAffinity",
    "as_affinity",
    "GaussianEdgeFactors",
    "gaussian_edge_affinity",
    "gaussian_edge_factors",
    "gaussian_node_affinity",
    "prefers_separable",
]


class Affinity(ABC):
    """Quadratic term of a Lawler QAP, accessed through products only.

    Attributes
    ----------
    n1, n2 : int
        Sizes of the two graphs.

    Examples
    --------
    >>> import numpy as np
    >>> from transync.matching import Affinity, as_affinity
    >>> aff = as_affinity(np.eye(4), n1=2, n2=2)       # K = I: the score counts the matches
    >>> isinstance(aff, Affinity), aff.shape, aff.score(np.eye(2))
    (True, (2, 2), 2.0)
    """

    n1: int
    n2: int

    @abstractmethod
    def matvec(self, X: np.ndarray) -> np.ndarray:
        """``reshape(K vec(X))`` for ``X`` of shape ``(n1, n2)``; returns shape ``(n1, n2)``."""

    def rmatvec(self, X: np.ndarray) -> np.ndarray:
        """``reshape(K^T vec(X))``. Symmetric affinities (undirected graphs) reuse ``matvec``."""
        return self.matvec(X)

    @abstractmethod
    def diag(self) -> np.ndarray:
        """Diagonal of ``K`` (the unary term) as an ``(n1, n2)`` array."""

    @abstractmethod
    def to_dense(self) -> np.ndarray:
        """The full ``(n1 n2, n1 n2)`` matrix in pygmtools' layout (small problems only)."""

    @property
    def shape(self) -> tuple[int, int]:
        return (self.n1, self.n2)

    def _block(self, X) -> np.ndarray:
        """``X`` as a real ``(n1, n2)`` float array (the products' argument check: shape and
        dtype only, the solvers call them at every step)."""
        X = np.asarray(X)
        if X.dtype.kind not in "biuf":
            raise TypeError(f"`X` must be a real array, got dtype {X.dtype}")
        if X.shape != (self.n1, self.n2):
            raise ValueError(f"`X` must have shape (n1, n2) = ({self.n1}, {self.n2}), got "
                             f"{X.shape}")
        return X.astype(float, copy=False)

    def score(self, X) -> float:
        """QAP objective ``vec(X)^T K vec(X)`` of a finite ``(n1, n2)`` matrix ``X``.

        Raises ``TypeError``/``ValueError`` for a complex, non-finite or mis-shaped ``X`` and
        for an ``X`` so large that the objective overflows float64.
        """
        X = check_array(X, "X", ndim=2)
        if X.shape != (self.n1, self.n2):
            raise ValueError(f"`X` must have shape (n1, n2) = ({self.n1}, {self.n2}), got "
                             f"{X.shape}")
        with np.errstate(over="ignore", invalid="ignore"):
            value = float(np.vdot(X, self.matvec(X)))
        if not np.isfinite(value):
            raise ValueError(f"the objective of `X` overflows float64 (largest |X| entry "
                             f"{float(np.abs(X).max()):.3g}; an assignment matrix has 0/1 "
                             "entries)")
        return value

    def column_sums(self) -> np.ndarray:
        """Column sums of ``K`` as an ``(n1, n2)`` array."""
        return self.rmatvec(np.ones((self.n1, self.n2)))

    def max_column_sum(self) -> float:
        return float(np.max(self.column_sums()))

    def drop_conflicts(self) -> Affinity:
        """Affinity with the entries linking conflicting candidates set to zero.

        Conflicting candidates share a node of one graph (``(i, a)`` and ``(i, b)``, ``a != b``).
        Edge-based backends have none unless a self-loop pairs with an edge (a self-loop in an
        edge list, a non-zero diagonal in a separable factor); without one they return ``self``.
        """
        return self

    def __repr__(self) -> str:
        return f"{type(self).__name__}(n1={self.n1}, n2={self.n2})"


def _vec(X: np.ndarray) -> np.ndarray:
    return np.asarray(X, dtype=float).ravel(order="F")


def _unvec(x: np.ndarray, n1: int, n2: int) -> np.ndarray:
    return np.asarray(x).reshape((n1, n2), order="F")


#: Most candidates ``n1 n2`` an affinity takes (every product allocates ``n1 n2`` floats) and
#: most entries ``(n1 n2)^2`` ``to_dense`` builds: 2**31 float64 are 16 GiB.
MAX_DENSE_ENTRIES = 2**31


def _check_sizes(n1, n2) -> tuple[int, int]:
    n1, n2 = check_int(n1, "n1", minimum=1), check_int(n2, "n2", minimum=1)
    if n1 * n2 > MAX_DENSE_ENTRIES:         # 10**12 x 10**12 was accepted, then a MemoryError
        raise ValueError(f"`n1` x `n2` must be at most {MAX_DENSE_ENTRIES} candidates, got "
                         f"{n1} x {n2}")
    return n1, n2


def _check_dense(aff) -> None:
    """Refuse ``to_dense`` when ``(n1 n2)^2`` entries exceed ``MAX_DENSE_ENTRIES``."""
    nn = aff.n1 * aff.n2
    if nn * nn > MAX_DENSE_ENTRIES:
        raise ValueError(f"to_dense() would build a {nn} x {nn} matrix ({float(nn) ** 2:.3g} "
                         f"entries, above {MAX_DENSE_ENTRIES}); use matvec() / the factorized "
                         "form")


def _check_values(values: np.ndarray, name: str, n_candidates: int) -> None:
    """Finite, non-negative and not so large that the solvers' sums overflow (``values``
    already a real float array)."""
    if not np.all(np.isfinite(values)):
        bad = int(values.size - np.count_nonzero(np.isfinite(values)))
        raise ValueError(f"`{name}` must be finite, got {bad} NaN or infinite entries")
    check_nonnegative(values, name)
    if values.size:
        check_affinity_magnitude(values.max(), n_candidates, name)


def _check_lawler_shape(K, n1: int, n2: int, name: str) -> None:
    if K.shape != (n1 * n2, n1 * n2):
        raise ValueError(f"`{name}` must have shape (n1*n2, n1*n2) = ({n1 * n2}, {n1 * n2}), "
                         f"got {K.shape}")


class _MatrixAffinity(Affinity):
    def __init__(self, K, n1: int, n2: int):
        self.K = K
        self.n1, self.n2 = n1, n2

    def matvec(self, X):
        return _unvec(self.K @ _vec(self._block(X)), self.n1, self.n2)

    def rmatvec(self, X):
        return _unvec(self.K.T @ _vec(self._block(X)), self.n1, self.n2)

    def _conflict_mask(self):
        n1, n2 = self.n1, self.n2
        idx = np.arange(n1 * n2)
        i, a = idx % n1, idx // n1
        return i, a


class DenseAffinity(_MatrixAffinity):
    """A dense ``K`` of shape ``(n1 n2, n1 n2)`` in pygmtools' column-major layout.

    ``K`` must be real, finite and non-negative (it need not be symmetric: the solvers that need
    symmetry use ``(K + K^T) / 2``, which has the same objective).

    Parameters
    ----------
    K : array_like of shape (n1 * n2, n1 * n2)
        The affinity matrix; candidate ``(i, a)`` has index ``a * n1 + i``.
    n1, n2 : int
        Sizes of the two graphs.
    name : str, default="K"
        The argument name used in error messages.

    Notes
    -----
    A float64 ``K`` is kept as given, not copied (as NumPy and SciPy keep their operands): the
    checks above hold for it as it was at construction, so do not modify it afterwards.

    Raises
    ------
    ValueError, TypeError
        ``K`` of the wrong shape, not real, or with NaN, infinite or negative entries.

    Examples
    --------
    >>> import numpy as np
    >>> from transync.matching import DenseAffinity
    >>> aff = DenseAffinity(np.eye(4), 2, 2)
    >>> aff.matvec(np.array([[1.0, 0.0], [0.0, 1.0]]))
    array([[1., 0.],
           [0., 1.]])
    >>> DenseAffinity(np.ones((4, 4)), 3, 3)
    Traceback (most recent call last):
    ...
    ValueError: `K` must have shape (n1*n2, n1*n2) = (9, 9), got (4, 4)
    """

    def __init__(self, K, n1: int, n2: int, *, name: str = "K"):
        n1, n2 = _check_sizes(n1, n2)
        K = check_array(K, name, ndim=2)
        _check_lawler_shape(K, n1, n2, name)
        _check_values(K, name, n1 * n2)
        super().__init__(K, n1, n2)

    def diag(self):
        return _unvec(np.diag(self.K), self.n1, self.n2)

    def to_dense(self):
        return np.array(self.K, dtype=float)

    def drop_conflicts(self):
        i, a = self._conflict_mask()
        conflict = ((i[:, None] == i[None, :]) ^ (a[:, None] == a[None, :]))
        return DenseAffinity(np.where(conflict, 0.0, self.K), self.n1, self.n2)


class SparseAffinity(_MatrixAffinity):
    """A ``scipy.sparse`` ``K`` of shape ``(n1 n2, n1 n2)`` in pygmtools' layout.

    Parameters
    ----------
    K : sparse matrix or array_like of shape (n1 * n2, n1 * n2)
        The affinity matrix (stored as CSR); candidate ``(i, a)`` has index ``a * n1 + i``.
    n1, n2 : int
        Sizes of the two graphs.
    name : str, default="K"
        The argument name used in error messages.

    Notes
    -----
    A float64 ``K`` is kept as given, not copied (as NumPy and SciPy keep their operands): the
    checks above hold for it as it was at construction, so do not modify it afterwards.

    Raises
    ------
    ValueError, TypeError
        ``K`` of the wrong shape, not real, or with NaN, infinite or negative entries.

    Examples
    --------
    >>> import scipy.sparse as sp
    >>> from transync.matching import SparseAffinity
    >>> aff = SparseAffinity(sp.identity(6), 2, 3)
    >>> aff.shape, float(aff.diag().sum())
    ((2, 3), 6.0)
    """

    def __init__(self, K, n1: int, n2: int, *, name: str = "K"):
        n1, n2 = _check_sizes(n1, n2)
        if not sp.issparse(K):
            K = check_array(K, name, ndim=2)
        elif np.iscomplexobj(K.data) or K.dtype.kind not in "biuf":
            raise TypeError(f"`{name}` must be a real sparse matrix, got dtype {K.dtype}")
        K = sp.csr_matrix(K, dtype=float)
        _check_lawler_shape(K, n1, n2, name)
        _check_values(K.data, name, n1 * n2)
        super().__init__(K, n1, n2)

    def diag(self):
        return _unvec(self.K.diagonal(), self.n1, self.n2)

    def to_dense(self):
        _check_dense(self)
        return self.K.toarray()

    def drop_conflicts(self):
        K = self.K.tocoo()
        i, a = self._conflict_mask()
        conflict = (i[K.row] == i[K.col]) ^ (a[K.row] == a[K.col])
        keep = ~conflict
        K2 = sp.csr_matrix((K.data[keep], (K.row[keep], K.col[keep])), shape=K.shape)
        return SparseAffinity(K2, self.n1, self.n2)


def _check_node_term(node, n1: int, n2: int):
    """``None`` or a finite non-negative ``(n1, n2)`` array (the diagonal of ``K``)."""
    if node is None:
        return None
    node = check_array(node, "node", ndim=2)
    if node.shape != (n1, n2):
        raise ValueError(f"`node` must have shape (n1, n2) = ({n1}, {n2}), got {node.shape}")
    _check_values(node, "node", n1 * n2)
    return node


def _check_edge_list(edges, n: int, name: str) -> np.ndarray:
    """An ``(m, 2)`` int array of node indices in ``[0, n)``."""
    E = check_array(edges, name, dtype=None)
    if E.size == 0:
        return np.zeros((0, 2), dtype=np.int64)
    if E.ndim != 2 or E.shape[1] != 2:
        raise ValueError(f"`{name}` must have shape (m, 2), got {E.shape}")
    E = check_int_array(E, name, integral_floats=True, what="integer node indices", copy=True)
    if E.min() < 0 or E.max() >= n:
        raise ValueError(f"`{name}` must hold node indices in [0, {n}), got range "
                         f"[{E.min()}, {E.max()}]")
    return E


class FactorizedAffinity(Affinity):
    """``K = diag(vec(node)) + sum over edge pairs``, never materialized.

    ``K[(i, a), (j, b)] += edge[e1, e2]`` for every directed edge ``e1 = (i, j)`` of graph 1 and
    ``e2 = (a, b)`` of graph 2. A product costs ``O(m1 m2 + n1 n2)``.

    Parameters
    ----------
    node : ndarray of shape (n1, n2) or None
        Unary term (the diagonal of ``K``); ``None`` for none.
    edge : ndarray of shape (m1, m2) or None
        Affinity of each pair of directed edges (edge ``e1`` of graph 1, ``e2`` of graph 2);
        ``None`` for zeros.
    edges1 : int ndarray of shape (m1, 2)
        Directed edges ``(i, j)`` of graph 1.
    edges2 : int ndarray of shape (m2, 2)
        Directed edges ``(a, b)`` of graph 2.
    n1, n2 : int
        Sizes of the two graphs.

    Raises
    ------
    ValueError, TypeError
        Mis-shaped terms, edge lists with indices out of range, NaN, infinite or negative
        affinities.

    Examples
    --------
    >>> import numpy as np
    >>> from transync.matching import FactorizedAffinity
    >>> edges = np.array([[0, 1], [1, 0]])
    >>> aff = FactorizedAffinity(None, np.ones((2, 2)), edges, edges, 2, 2)
    >>> aff.score(np.eye(2)), aff.score(np.eye(2)[::-1])
    (2.0, 2.0)
    """

    def __init__(self, node, edge, edges1, edges2, n1: int, n2: int):
        n1, n2 = _check_sizes(n1, n2)
        self.n1, self.n2 = n1, n2
        self.node = _check_node_term(node, n1, n2)
        self.edges1 = _check_edge_list(edges1, n1, "edges1")
        self.edges2 = _check_edge_list(edges2, n2, "edges2")
        m1, m2 = len(self.edges1), len(self.edges2)
        if edge is None:
            self.edge = np.zeros((m1, m2))
        else:
            self.edge = check_array(edge, "edge", ndim=2)
            if self.edge.shape != (m1, m2):
                raise ValueError(f"`edge` must have shape (m1, m2) = ({m1}, {m2}), the lengths of "
                                 f"`edges1` and `edges2`, got {self.edge.shape}")
            _check_values(self.edge, "edge", n1 * n2)
        ones1, ones2 = np.ones(m1), np.ones(m2)
        self._S1 = sp.csr_matrix((ones1, (self.edges1[:, 0], np.arange(m1))), shape=(n1, m1))
        self._S2T = sp.csc_matrix((ones2, (np.arange(m2), self.edges2[:, 0])), shape=(m2, n2))
        self._T1 = sp.csr_matrix((ones1, (self.edges1[:, 1], np.arange(m1))), shape=(n1, m1))
        self._T2T = sp.csc_matrix((ones2, (np.arange(m2), self.edges2[:, 1])), shape=(m2, n2))

    def _product(self, X, end: int, S1, S2T):
        """``K vec(X)`` (``end=1``: gather at edge heads, scatter to tails) or ``K^T vec(X)``."""
        X = self._block(X)
        W = self.edge * X[np.ix_(self.edges1[:, end], self.edges2[:, end])]
        Y = np.asarray((S1 @ W) @ S2T) if W.size else np.zeros((self.n1, self.n2))
        if self.node is not None:
            Y = Y + self.node * X
        return Y

    def matvec(self, X):
        return self._product(X, 1, self._S1, self._S2T)

    def rmatvec(self, X):
        return self._product(X, 0, self._T1, self._T2T)

    def diag(self):
        return np.zeros((self.n1, self.n2)) if self.node is None else self.node.copy()

    def drop_conflicts(self) -> Affinity:
        """``self``, or a copy without the edge pairs that join a self-loop of one graph to an
        edge of the other (their entries link conflicting candidates)."""
        loop1 = self.edges1[:, 0] == self.edges1[:, 1]
        loop2 = self.edges2[:, 0] == self.edges2[:, 1]
        conflict = loop1[:, None] != loop2[None, :]
        if not (conflict & (self.edge != 0)).any():
            return self
        return FactorizedAffinity(self.node, np.where(conflict, 0.0, self.edge), self.edges1,
                                  self.edges2, self.n1, self.n2)

    def to_dense(self):
        _check_dense(self)
        n1 = self.n1
        K = np.zeros((n1 * self.n2, n1 * self.n2))
        rows = self.edges2[:, 0][None, :] * n1 + self.edges1[:, 0][:, None]
        cols = self.edges2[:, 1][None, :] * n1 + self.edges1[:, 1][:, None]
        np.add.at(K, (rows.ravel(), cols.ravel()), self.edge.ravel())
        K[np.diag_indices_from(K)] += _vec(self.diag())
        return K


class SeparableAffinity(Affinity):
    """``K = diag(vec(node)) + sum_r G_r (x) F_r``: a sum of Kronecker products.

    ``K[(i, a), (j, b)] = node[i, a] [i == j, a == b] + sum_r F[r, i, j] G[r, a, b]``; the
    product is ``Y = node * X + sum_r F_r X G_r^T`` at ``O(R (n1^2 n2 + n1 n2^2))``.

    Parameters
    ----------
    node : ndarray of shape (n1, n2) or None
        Unary term (added to the diagonal of ``K``); ``None`` for none.
    F : ndarray of shape (R, n1, n1)
        Factors on graph 1.
    G : ndarray of shape (R, n2, n2)
        Factors on graph 2.
    max_error : float, default=0.0
        Bound on ``|K_exact - K|`` entrywise, estimated when the expansion was built (0 if exact);
        stored as the attribute of the same name.

    Raises
    ------
    ValueError, TypeError
        Mis-shaped factors (``R`` or a size of 0, ``G`` with another rank than ``F``), factors
        so large that ``R max|F| max|G|`` times ``n1 n2`` exceeds 1e300 (products overflow), a
        mis-shaped or negative ``node``, a negative ``max_error``.

    Examples
    --------
    >>> import numpy as np
    >>> from transync.matching import SeparableAffinity
    >>> F, G = np.ones((1, 2, 2)), np.ones((1, 3, 3))      # rank 1: K is all ones
    >>> aff = SeparableAffinity(None, F, G)
    >>> aff.rank, aff.shape, bool(np.allclose(aff.to_dense(), 1.0))
    (1, (2, 3), True)
    """

    def __init__(self, node, F, G, *, max_error: float = 0.0):
        self.F = np.ascontiguousarray(check_array(F, "F", ndim=3))
        self.G = np.ascontiguousarray(check_array(G, "G", ndim=3))
        R, n1, n1b = self.F.shape
        if R == 0 or n1 == 0 or n1 != n1b:
            raise ValueError(f"`F` must have shape (R, n1, n1) with R, n1 >= 1, got {self.F.shape}")
        if self.G.shape[0] != R or self.G.shape[1] == 0 or self.G.shape[1] != self.G.shape[2]:
            raise ValueError(f"`G` must have shape (R, n2, n2) with R={R} (as `F`) and n2 >= 1, "
                             f"got {self.G.shape}")
        self.n1, self.n2 = n1, self.G.shape[1]
        with np.errstate(over="ignore"):        # inf here is refused below
            bound = R * float(np.abs(self.F).max()) * float(np.abs(self.G).max())
        # |K| <= R max|F| max|G| entrywise: factors of 1e300 passed and every product overflowed
        check_affinity_magnitude(bound, self.n1 * self.n2, "F, G")
        self.node = _check_node_term(node, self.n1, self.n2)
        self.max_error = check_positive(max_error, "max_error", allow_zero=True)
        # concatenated factors turn the R small products into two large GEMMs
        self._Gcat = np.ascontiguousarray(np.swapaxes(self.G, 1, 2).transpose(1, 0, 2)
                                          .reshape(self.n2, R * self.n2))
        self._Fcat = np.ascontiguousarray(self.F.transpose(1, 0, 2).reshape(self.n1, R * self.n1))
        self._transposed = None  # factors of K^T, built on the first rmatvec
        self._symmetric = None   # `symmetric`, computed on first use
        # K's entries are not formed; a diagonal entry, or a row sum of n1 n2 entries, below
        # zero by more than the expansion's error (and rounding) per entry proves negative
        # ones, which the solvers cannot take
        tol = self.max_error + 1e-12 * bound
        row_sum = float(self.matvec(np.ones((self.n1, self.n2))).min())
        diagonal = float(self.diag().min())
        if diagonal < -tol or row_sum < -tol * self.n1 * self.n2:
            raise ValueError(f"`F`, `G` give a K with negative entries (smallest diagonal "
                             f"entry {diagonal:.3g}, smallest row sum {row_sum:.3g}, beyond the "
                             f"expansion's error bound max_error={self.max_error:g}); an "
                             "affinity is non-negative")

    @property
    def rank(self) -> int:
        return self.F.shape[0]

    def _product(self, X, Fcat, Gcat):
        X = self._block(X)
        R, n1, n2 = self.F.shape[0], self.n1, self.n2
        Z = (X @ Gcat).reshape(n1, R, n2).transpose(1, 0, 2).reshape(R * n1, n2)
        Y = Fcat @ Z
        if self.node is not None:
            Y += self.node * X
        return Y

    def matvec(self, X):
        return self._product(X, self._Fcat, self._Gcat)

    @property
    def symmetric(self) -> bool:
        """Whether ``K`` is symmetric, read off the factors (symmetric ``F_r`` and ``G_r``, as
        undirected graphs give); computed once."""
        if self._symmetric is None:
            self._symmetric = bool(np.array_equal(self.F, np.swapaxes(self.F, 1, 2))
                                   and np.array_equal(self.G, np.swapaxes(self.G, 1, 2)))
        return self._symmetric

    def rmatvec(self, X):
        if self._transposed is None:
            R = self.F.shape[0]
            if self.symmetric:
                self._transposed = (self._Fcat, self._Gcat)   # undirected: K is symmetric
            else:
                self._transposed = (
                    np.ascontiguousarray(np.swapaxes(self.F, 1, 2).transpose(1, 0, 2)
                                         .reshape(self.n1, R * self.n1)),
                    np.ascontiguousarray(self.G.transpose(1, 0, 2).reshape(self.n2, R * self.n2)))
        return self._product(X, *self._transposed)

    def diag(self):
        d = np.einsum("rii,raa->ia", self.F, self.G)
        return d if self.node is None else d + self.node

    def drop_conflicts(self) -> Affinity:
        """``self``, or the expansion without the products of a factor's diagonal with the other
        factor's off-diagonal part (the entries linking conflicting candidates): rank ``2R``,
        ``sum_r offdiag(F_r) (x) offdiag(G_r) + diag(F_r) (x) diag(G_r)``."""
        dF = np.diagonal(self.F, axis1=1, axis2=2)
        dG = np.diagonal(self.G, axis1=1, axis2=2)
        if not (dF.any() or dG.any()):
            return self
        eye1, eye2 = np.eye(self.n1, dtype=bool), np.eye(self.n2, dtype=bool)
        F = np.concatenate([np.where(eye1, 0.0, self.F), np.where(eye1, self.F, 0.0)])
        G = np.concatenate([np.where(eye2, 0.0, self.G), np.where(eye2, self.G, 0.0)])
        return SeparableAffinity(self.node, F, G, max_error=self.max_error)

    def to_dense(self):
        """The full matrix; entries an expansion (``max_error > 0``) puts below zero by less
        than its error bound are 0, so that ``as_affinity(a.to_dense())`` accepts it."""
        _check_dense(self)
        K = np.einsum("rij,rab->aibj", self.F, self.G).reshape(self.n1 * self.n2, -1)
        if self.node is not None:
            K[np.diag_indices_from(K)] += _vec(self.node)
        if self.max_error > 0:
            K[(K < 0) & (K >= -self.max_error)] = 0.0
        return K


# --------------------------------------------------------------------------- construction


class _CheckedAffinity(Affinity):
    """A user's :class:`Affinity` subclass whose every output is checked: arrays of the promised
    shape, finite; an error names the argument and the method (a ``matvec`` returning ``None``,
    NaN or a wrong shape surfaced as an unrelated error deep in a solver)."""

    def __init__(self, inner: Affinity, name: str):
        self._inner, self._arg = inner, name
        self.n1 = check_int(getattr(inner, "n1", None), f"{name}.n1", minimum=1)
        self.n2 = check_int(getattr(inner, "n2", None), f"{name}.n2", minimum=1)

    def __getattr__(self, attr):             # the user's own attributes (not found above)
        if attr == "_inner":                 # not yet set (unpickling): no recursion
            raise AttributeError(attr)
        return getattr(self._inner, attr)

    def _overrides(self, method: str) -> bool:
        return getattr(type(self._inner), method) is not getattr(Affinity, method)

    def _array(self, value, method: str, shape) -> np.ndarray:
        where = f"`{self._arg}`.{method}() (a {type(self._inner).__name__})"
        if value is None:
            raise TypeError(f"{where} must return a float array of shape {shape}, got None")
        if np.iscomplexobj(value):
            raise TypeError(f"{where} must return a real array, got a complex one")
        try:
            arr = np.asarray(value, dtype=float)
        except (TypeError, ValueError):
            raise TypeError(f"{where} must return a float array of shape {shape}, got "
                            f"{type(value).__name__}") from None
        if arr.shape != shape:
            raise ValueError(f"{where} must return an array of shape {shape}, got shape "
                             f"{arr.shape}")
        if not np.all(np.isfinite(arr)):
            bad = int(arr.size - np.count_nonzero(np.isfinite(arr)))
            raise ValueError(f"{where} returned {bad} NaN or infinite entries")
        return arr

    def matvec(self, X):
        return self._array(self._inner.matvec(X), "matvec", (self.n1, self.n2))

    def rmatvec(self, X):
        if not self._overrides("rmatvec"):
            return Affinity.rmatvec(self, X)   # through the checked matvec
        return self._array(self._inner.rmatvec(X), "rmatvec", (self.n1, self.n2))

    def diag(self):
        return self._array(self._inner.diag(), "diag", (self.n1, self.n2))

    def to_dense(self):
        m = self.n1 * self.n2
        return self._array(self._inner.to_dense(), "to_dense", (m, m))

    def score(self, X) -> float:
        if not self._overrides("score"):
            return Affinity.score(self, X)   # through the checked matvec
        value = self._array(self._inner.score(X), "score", ())
        return float(value)

    def column_sums(self):
        if not self._overrides("column_sums"):
            return Affinity.column_sums(self)
        return self._array(self._inner.column_sums(), "column_sums", (self.n1, self.n2))

    def drop_conflicts(self) -> Affinity:
        out = self._inner.drop_conflicts()
        return self if out is self._inner else as_affinity(out, name=self._arg)

    def __repr__(self) -> str:
        return repr(self._inner)


def as_affinity(K, *, n1: int | None = None, n2: int | None = None, name: str = "K") -> Affinity:
    """Wrap a pygmtools-style ``K`` (dense or sparse) as an :class:`Affinity`; pass through others.

    Parameters
    ----------
    K : Affinity, array_like or sparse matrix
        An :class:`Affinity` (the library's own classes returned as is; a subclass of the
        user's comes back wrapped, so that every output of its methods is checked: shape,
        finite values) or a matrix of shape ``(n1 n2, n1 n2)`` in pygmtools' column-major
        layout.
    n1, n2 : int, optional
        Sizes of the two graphs: required for a matrix, checked against an :class:`Affinity`.
    name : str, default="K"
        The argument name used in error messages.

    Returns
    -------
    Affinity
        ``K`` itself (a user's subclass: ``K`` behind a checking wrapper), a
        :class:`SparseAffinity` for a sparse matrix, else a :class:`DenseAffinity`.

    Raises
    ------
    ValueError
        ``K`` is not square, not ``(n1 n2, n1 n2)``, has NaN/inf or negative entries, or is an
        :class:`Affinity` of other sizes than ``n1``, ``n2``.
    TypeError
        ``n1`` or ``n2`` missing for a matrix.

    Examples
    --------
    >>> import numpy as np
    >>> from transync.matching import as_affinity
    >>> aff = as_affinity(np.eye(6), n1=2, n2=3)
    >>> type(aff).__name__, aff.shape, as_affinity(aff) is aff
    ('DenseAffinity', (2, 3), True)
    """
    if isinstance(K, Affinity):
        if (n1 is not None and n1 != K.n1) or (n2 is not None and n2 != K.n2):
            raise ValueError(f"`{name}` is an Affinity of shape {K.shape}, but n1={n1}, n2={n2} "
                             "were given")
        if type(K).__module__.split(".")[0] == "transync":
            return K
        return _CheckedAffinity(K, name)         # a user's subclass: its outputs are checked
    if n1 is None or n2 is None:
        raise TypeError(f"`n1` and `n2` are required when `{name}` is a matrix, got n1={n1!r}, "
                        f"n2={n2!r}")
    if sp.issparse(K):
        return SparseAffinity(K, n1, n2, name=name)
    return DenseAffinity(K, n1, n2, name=name)


def gaussian_node_affinity(g1: Graph, g2: Graph, *, sigma2: float = 1.0,
                           attribute: str = "features") -> np.ndarray:
    """Unary affinity ``exp(-||f1_i - f2_a||^2 / sigma2)`` of shape ``(n1, n2)``.

    Parameters
    ----------
    g1, g2 : Graph
        The two graphs, with node features (or points) of the same dimension.
    sigma2 : float, default=1.0
        Kernel width.
    attribute : {"features", "points"}, default="features"
        Compare the graphs' ``node_features`` or their ``points``.

    Returns
    -------
    ndarray of shape (n1, n2)
        ``exp(-||f1_i - f2_a||^2 / sigma2)``, the unary term of a Lawler QAP (``node_affinity``
        of :func:`gaussian_edge_affinity`).

    Raises
    ------
    ValueError, TypeError
        Arguments that are not graphs, an unknown ``attribute``, a graph without it, features of
        different dimensions, a non-positive ``sigma2``.
    DegenerateInputError
        Every entry underflows (``sigma2`` far below the squared scale of the features); the
        message suggests a ``sigma2``.

    Examples
    --------
    >>> import numpy as np
    >>> from transync.graphs import Graph
    >>> from transync.matching import gaussian_node_affinity
    >>> g = Graph.from_points(np.array([[0.0, 0.0], [1.0, 0.0]]), edges="full")
    >>> gaussian_node_affinity(g, g, attribute="points").round(3)
    array([[1.   , 0.368],
           [0.368, 1.   ]])
    """
    if not isinstance(g1, Graph) or not isinstance(g2, Graph):
        raise TypeError(f"`g1` and `g2` must be Graph objects, got {type(g1).__name__} and "
                        f"{type(g2).__name__}")
    check_choice(attribute, "attribute", ("features", "points"))
    sigma2 = check_positive(sigma2, "sigma2")
    f1 = g1.node_features if attribute == "features" else g1.points
    f2 = g2.node_features if attribute == "features" else g2.points
    if f1 is None or f2 is None:
        need = "node_features" if attribute == "features" else "points"
        raise ValueError(f"both graphs need `{need}`"
                         " for a node affinity")
    if f1.shape[1] != f2.shape[1]:
        what = "node_features" if attribute == "features" else "points"
        raise ValueError(f"`g1.{what}` and `g2.{what}` must have the same width, got "
                         f"{f1.shape[1]} and {f2.shape[1]}")
    if f1.shape[1] == 0:                    # every node alike: a node affinity of all ones
        what = "node_features" if attribute == "features" else "points"
        raise ValueError(f"`g1.{what}` and `g2.{what}` have no columns (shape "
                         f"{f1.shape}): there is nothing to compare nodes by")
    # d2 / sigma2 on features scaled by a power of two: points at 1e200 squared to inf before
    top = max(float(np.abs(f1).max(initial=0.0)), float(np.abs(f2).max(initial=0.0)))
    e = int(np.frexp(top)[1]) if top > 0 else 0
    D = np.ldexp(f1, -e)[:, None, :] - np.ldexp(f2, -e)[None, :, :]
    with np.errstate(over="ignore"):        # beyond float64: exp(-inf) = 0, refused below
        # scaling by 2**e commutes with rounding: d2 / sigma2 to the last bit where it is finite
        t = np.ldexp((D ** 2).sum(-1), 2 * e) / sigma2
    _refuse_underflow(int(np.count_nonzero(t <= _UNDERFLOW)), 1, sigma2,
                      f"node {attribute}", float(np.median(np.abs(np.concatenate(
                          [f1.ravel(), f2.ravel()])))))
    return np.exp(-t)


#: Default width ``sigma2`` of the Gaussian edge affinity ``exp(-(d1 - d2)^2 / sigma2)`` (Cho et
#: al.'s 0.15; methods page *Synthetic protocols and evaluation measures*): the one default of
#: :func:`gaussian_edge_affinity`,
#: :func:`gaussian_edge_factors`, :func:`~transync.matching.match_graphs`,
#: :func:`~transync.match_collection` and ``transync match --sigma2``.
DEFAULT_SIGMA2 = 0.15

# exp(-t) for t above this is below 1e-300: the Gaussian kernel has underflowed
_UNDERFLOW = 690.0

# largest edge length whose square (and a Gaussian width for it) float64 still holds
_MAX_LENGTH = 1e150


def _refuse_underflow(alive: int, needed: int, sigma2: float, what: str, scale: float) -> None:
    """Raise when fewer than ``needed`` pairs keep a non-negligible ``exp(-d2 / sigma2)``.

    A vanishing Gaussian affinity makes every solver return an arbitrary matching with objective
    (about) 0 and ``converged=True``; the cause is a ``sigma2`` far below the squared scale of
    the data (coordinates in pixels or metres with the unit-square default, say).
    """
    if alive >= needed:
        return
    # no default value nor function name here: the CLI's commands have other defaults and its
    # user called none of the library functions
    fix = (f"Set `sigma2` to about the squared scale of the data (e.g. "
           f"sigma2={0.6 * scale**2:.3g}), or rescale the data"
           if scale < 1e150 else        # its square is beyond float64: no sigma2 can help
           "Rescale the data (its squared scale is beyond float64)")
    raise DegenerateInputError(
        f"`sigma2`={sigma2:g} is too small for {what} of magnitude ~{scale:.3g}: only {alive} "
        f"pair(s) keep a Gaussian affinity exp(-d^2 / sigma2) above 1e-300 (at least {needed} "
        f"needed), so any matching would score about 0. {fix}")


def _count_close(x_sorted: np.ndarray, y: np.ndarray, radius: float) -> int:
    """Number of pairs ``(i, j)`` with ``|x_i - y_j| <= radius`` (binary search in sorted ``x``)."""
    hi = np.searchsorted(x_sorted, y + radius, side="right")
    lo = np.searchsorted(x_sorted, y - radius, side="left")
    return int((hi - lo).sum())


def _edge_attributes(g: Graph, attribute: str, name: str) -> list[np.ndarray]:
    if attribute in ("weight", "features"):
        if attribute == "features" and g.edge_features is None:
            raise ValueError(f"attribute='features' needs graphs with `edge_features`; `{name}` "
                             "has none")
        E, what = ((g.adjacency, "adjacency weights") if attribute == "weight"
                   else (g.edge_features, "edge_features"))
        top = float(np.abs(E).max())
        if top > _MAX_LENGTH:
            raise ValueError(f"the {what} of `{name}` overflow when their differences are "
                             f"squared (up to {top:.3g}, at most {_MAX_LENGTH:g} taken); rescale "
                             "them")
        return [E]
    if g.points is None:
        raise ValueError(f"attribute={attribute!r} needs graphs with `points`; `{name}` has none "
                         "(use attribute='weight' or 'features')")
    with np.errstate(over="ignore", invalid="ignore"):
        D = g.distances()
    if not np.all(np.isfinite(D)) or D.max(initial=0.0) > _MAX_LENGTH:
        raise ValueError(f"the edge lengths of `{name}` overflow when squared (lengths up to "
                         f"{D.max(initial=0.0):.3g}, points of magnitude up to "
                         f"{np.abs(g.points).max():.3g}); rescale the points")
    return [D] if attribute == "length" else [D, g.angles()]


def gaussian_edge_affinity(g1: Graph, g2: Graph, *, sigma2: float = DEFAULT_SIGMA2,
                           attribute: str | None = None, angle_weight: float = 0.1,
                           node_affinity=None, backend: str = "auto",
                           tol: float = 1e-10) -> Affinity:
    """Cho et al.'s Gaussian edge affinity ``K[(i,a),(j,b)] = exp(-(e1_ij - e2_ab)^2 / sigma2)``.

    Entries are non-zero only when ``(i, j)`` is an edge of ``g1`` and ``(a, b)`` an edge of
    ``g2`` (directed: both directions of undirected edges). This is the same matrix as pygmtools'
    ``build_aff_mat`` with ``gaussian_aff_fn(sigma=sigma2)`` on the same edge features.

    Parameters
    ----------
    g1, g2 : Graph
        The two graphs (points, adjacency weights or edge features, per ``attribute``).
    sigma2 : float, default=0.15
        Kernel width (Cho et al. use 0.15 on U(0, 1) attributes; Yan et al. 0.05).
    attribute : {"length", "weight", "features", "length+angle"}, optional
        Edge attribute: point distances, adjacency weights, the graphs' scalar ``edge_features``,
        or distance plus wrapped angle difference weighted by ``angle_weight``
        (``exp(-(dd^2 + angle_weight * dtheta^2) / sigma2)``). Default: ``"features"`` when both
        graphs have edge features, else ``"length"`` when both have points, else ``"weight"``.
    angle_weight : float, default=0.1
        Weight of the squared angle difference for ``attribute="length+angle"``.
    node_affinity : ndarray of shape (n1, n2), optional
        Unary term on the diagonal of ``K``.
    backend : {"auto", "separable", "factorized", "sparse", "dense"}, default="auto"
        ``"auto"`` picks the separable expansion when it is cheaper than the factorized form (dense
        graphs, scalar attributes) and its achieved error is at most
        :data:`MAX_SEPARABLE_ERROR` (1e-6), else the factorized form. Neither forms ``K``.
    tol : float, default=1e-10
        Target entrywise accuracy of the separable expansion.

    Returns
    -------
    Affinity
        The affinity in the chosen backend (:class:`SeparableAffinity`,
        :class:`FactorizedAffinity`, :class:`SparseAffinity` or :class:`DenseAffinity`).

    Raises
    ------
    ValueError, TypeError
        Arguments that are not graphs, unknown options, a mis-shaped or negative
        ``node_affinity``, graphs without the requested attribute, points of different dimensions.
    DegenerateInputError
        ``sigma2`` so small for the scale of the attributes that fewer edge pairs than edges keep
        an affinity above 1e-300 (points in pixels with the unit-square default, say): the
        message suggests a ``sigma2``. Never a silent all-zero affinity.

    Examples
    --------
    >>> import numpy as np
    >>> from transync.graphs import Graph
    >>> from transync.matching import gaussian_edge_affinity
    >>> g = Graph.from_points(np.array([[0.0, 0.0], [1.0, 0.0], [0.0, 2.0]]), edges="full")
    >>> aff = gaussian_edge_affinity(g, g, backend="factorized")
    >>> type(aff).__name__, aff.shape
    ('FactorizedAffinity', (3, 3))
    >>> bool(aff.score(np.eye(3)) > aff.score(np.eye(3)[[1, 0, 2]]))   # truth scores higher
    True
    """
    if not isinstance(g1, Graph) or not isinstance(g2, Graph):
        raise TypeError(f"`g1` and `g2` must be Graph objects, got {type(g1).__name__} and "
                        f"{type(g2).__name__}")
    sigma2 = check_positive(sigma2, "sigma2")
    angle_weight = check_positive(angle_weight, "angle_weight", allow_zero=True)
    tol = check_positive(tol, "tol")
    if attribute is None:
        if g1.edge_features is not None and g2.edge_features is not None:
            attribute = "features"
        elif g1.points is not None and g2.points is not None:
            attribute = "length"
        else:
            attribute = "weight"
    check_choice(attribute, "attribute", ("length", "weight", "features", "length+angle"))
    check_choice(backend, "backend", ("auto", "separable", "factorized", "sparse", "dense"))
    if attribute.startswith("length") and g1.points is not None and g2.points is not None:
        d1, d2 = g1.points.shape[1], g2.points.shape[1]
        if d1 != d2:
            raise ValueError(f"`g1` and `g2` must have points of the same dimension for "
                             f"attribute={attribute!r}, got {d1} and {d2}")
    n1, n2 = g1.n_nodes, g2.n_nodes
    if node_affinity is not None:
        node_affinity = check_array(node_affinity, "node_affinity", ndim=2)
        if node_affinity.shape != (n1, n2):
            raise ValueError(f"`node_affinity` must have shape ({n1}, {n2}), "
                             f"got {node_affinity.shape}")
        _check_values(node_affinity, "node_affinity", n1 * n2)   # non-negative, not too large
    a1, a2 = _edge_attributes(g1, attribute, "g1"), _edge_attributes(g2, attribute, "g2")
    M1, M2 = g1.mask, g2.mask
    m1, m2 = int(M1.sum()), int(M2.sum())
    if m1 and m2:
        # each edge of the smaller graph needs a partner with a non-vanishing affinity
        x, y = np.sort(a1[0][M1]), a2[0][M2]
        _refuse_underflow(_count_close(x, y, np.sqrt(_UNDERFLOW * sigma2)), min(m1, m2), sigma2,
                          f"edge attributes ({attribute!r})",
                          float(np.median(np.abs(np.concatenate([x, y])))))
    if backend == "auto":
        scalar = attribute != "length+angle"
        backend = ("auto-separable" if scalar and bool(prefers_separable(n1, n2, m1, m2))
                   else "factorized")
    if backend in ("separable", "auto-separable"):
        if attribute == "length+angle":
            raise ValueError("`backend='separable'` supports scalar edge attributes only "
                             "('length', 'weight' or 'features'), got attribute='length+angle'")
        sep = _separable_gaussian(a1[0], a2[0], M1, M2, sigma2, node_affinity, tol)
        if backend == "separable" or sep.max_error <= MAX_SEPARABLE_ERROR:
            return sep
        backend = "factorized"         # "auto": an expansion too coarse is not used as is
    e1, e2 = np.argwhere(M1), np.argwhere(M2)
    d2 = (a1[0][M1][:, None] - a2[0][M2][None, :]) ** 2
    if attribute == "length+angle":
        dth = a1[1][M1][:, None] - a2[1][M2][None, :]
        dth = (dth + np.pi) % (2 * np.pi) - np.pi
        d2 = d2 + angle_weight * dth**2
    with np.errstate(over="ignore"):        # subnormal sigma2: d2 / sigma2 = inf, exp(-inf) = 0
        edge = np.exp(-d2 / sigma2)
    fac = FactorizedAffinity(node_affinity, edge, e1, e2, n1, n2)
    if backend == "factorized":
        return fac
    K = fac.to_dense()
    return DenseAffinity(K, n1, n2) if backend == "dense" else SparseAffinity(K, n1, n2)


def prefers_separable(n1, n2, m1, m2):
    """Whether a Gaussian edge affinity on scalar edge attributes is cheaper to multiply by in
    its separable expansion than in its factorized form: the rule of
    :func:`gaussian_edge_affinity` with ``backend="auto"``.

    For graphs of ``n1``, ``n2`` nodes and ``m1``, ``m2`` (directed) edges: ``n1^2 n2 + n1 n2^2
    < m1 m2``. One factorized entry (fancy indexing + sparse products) costs about as much as
    16 GEMM flops of the separable product (measured on 2 cores, n = 10..50, full graphs), and a
    separable product costs ``16 (n1^2 n2 + n1 n2^2)`` per expansion term in those units.
    Array arguments broadcast (one answer per pair).

    Examples
    --------
    >>> bool(prefers_separable(20, 20, 380, 380))    # complete graphs
    True
    >>> bool(prefers_separable(20, 20, 108, 108))    # Delaunay-like: 54 undirected edges
    False
    >>> prefers_separable([20, 20], [6, 2], [380, 380], [30, 2]).tolist()
    [True, False]
    """
    counts = []
    for name, v in (("n1", n1), ("n2", n2), ("m1", m1), ("m2", m2)):
        v = check_int_array(v, name, what="counts of nodes or edges")
        if v.size and v.min() < 0:
            raise ValueError(f"`{name}` must be >= 0, got {v.min()}")
        counts.append(v.astype(float))  # products in float: no int64 wrap-around
    n1, n2, m1, m2 = counts
    return n1 * n1 * n2 + n1 * n2 * n2 < m1 * m2


def _small_svd(C: np.ndarray):
    """SVD of the (p, p) kernel samples, p <= 200, on one BLAS thread (threads only add
    start-up cost at this size, measured up to 150 ms on a loaded 2-core machine)."""
    with blas_limit():
        return np.linalg.svd(C)


def _chebyshev_nodes(lo: float, hi: float, p: int) -> np.ndarray:
    k = np.arange(p)
    x = np.cos(np.pi * (2 * k + 1) / (2 * p))
    return 0.5 * (lo + hi) + 0.5 * (hi - lo) * x


#: largest entrywise error of a separable expansion that ``backend="auto"`` uses as is; above it
#: the exact factorized form is built instead (``backend="separable"`` returns it, reported)
MAX_SEPARABLE_ERROR = 1e-6


def _interpolation_interval(lo: float, hi: float, sigma2: float) -> tuple[float, float]:
    """``[lo, hi]`` widened so that the Chebyshev nodes on it are distinct in float64.

    Relative to the values' magnitude (and the kernel's width), not absolute: a range of one
    value (every edge attribute equal, e.g. unweighted graphs with ``attribute="weight"``) was
    widened by 1e-21, which rounds away at 1.0; all nodes then coincided, every basis function
    was 1 at every value and the expansion summed ``p`` of them (an edge affinity of 144 instead
    of 1 for ``p = 12``). A width of at least 2e-10 of the magnitude keeps the nodes at least
    2e-14 of it apart (``p <= 200``: about 100 units in the last place); ranges wider than a
    tenth of the magnitude keep their old padding, and their expansions bit for bit.
    """
    scale = max(abs(lo), abs(hi), float(np.sqrt(sigma2)))
    pad = max((hi - lo) * 1e-9, scale * 1e-10)
    return lo - pad, hi + pad


def _lagrange_basis(x: np.ndarray, nodes: np.ndarray) -> np.ndarray:
    """Barycentric Lagrange basis at ``x`` for Chebyshev points of the first kind; shape
    (len(x), p)."""
    p = nodes.size
    k = np.arange(p)
    w = (-1.0) ** k * np.sin(np.pi * (2 * k + 1) / (2 * p))
    diff = x[:, None] - nodes[None, :]
    exact = diff == 0
    diff[exact] = 1.0
    B = w[None, :] / diff
    B /= B.sum(1, keepdims=True)
    hit = exact.any(1)
    if hit.any():
        B[hit] = exact[hit].astype(float)
    return B


def _separable_gaussian(E1, E2, M1, M2, sigma2, node, tol):
    """Low-rank expansion of ``exp(-(x - y)^2 / sigma2)`` on the ranges of ``E1[M1]``, ``E2[M2]``.

    Tensor Chebyshev interpolation on ``p`` points per axis, recompressed by an SVD of the
    ``p x p`` kernel samples and truncated where the singular values fall below ``tol``; the
    achieved error is measured on a fine grid covering both ranges (and on the actual values).
    A subnormal ``sigma2`` makes ``d^2 / sigma2`` overflow to inf, whose ``exp(-inf) = 0`` is
    the right value: the overflow is not reported (the caller refuses a vanished affinity).
    """
    with np.errstate(over="ignore", divide="ignore"):
        return _separable_gaussian_expansion(E1, E2, M1, M2, sigma2, node, tol)


def _separable_gaussian_expansion(E1, E2, M1, M2, sigma2, node, tol):
    x = E1[M1]
    y = E2[M2]
    if x.size == 0 or y.size == 0:
        F = np.zeros((1,) + E1.shape)
        G = np.zeros((1,) + E2.shape)
        return SeparableAffinity(node, F, G, max_error=0.0)
    lo1, hi1 = _interpolation_interval(float(x.min()), float(x.max()), sigma2)
    lo2, hi2 = _interpolation_interval(float(y.min()), float(y.max()), sigma2)
    span = max(hi1, hi2) - min(lo1, lo2)
    # points per axis: enough for the Gaussian's width over the span (analytic, fast convergence)
    p = int(np.clip(np.ceil(8 + 4.0 * span / np.sqrt(sigma2)), 12, 200))
    cx, cy = _chebyshev_nodes(lo1, hi1, p), _chebyshev_nodes(lo2, hi2, p)
    C = np.exp(-((cx[:, None] - cy[None, :]) ** 2) / sigma2)
    U, s, Vt = _small_svd(C)
    R = int(np.searchsorted(-s, -tol * 0.1)) or 1
    R = max(1, min(R, p))
    A = U[:, :R] * np.sqrt(s[:R])          # (p, R)
    B = Vt[:R].T * np.sqrt(s[:R])          # (p, R)
    fx = _lagrange_basis(x, cx) @ A        # (m1, R)
    gy = _lagrange_basis(y, cy) @ B        # (m2, R)
    F = _scatter_factors(fx, M1)
    G = _scatter_factors(gy, M2)
    # a-posteriori error on a fine grid over the box, plus a sample of actual value pairs
    gx = np.linspace(lo1, hi1, 129)
    gyy = np.linspace(lo2, hi2, 129)
    approx = (_lagrange_basis(gx, cx) @ A) @ (_lagrange_basis(gyy, cy) @ B).T
    err = np.abs(approx - np.exp(-((gx[:, None] - gyy[None, :]) ** 2) / sigma2)).max()
    rng = np.random.default_rng(0)
    ix = rng.integers(0, x.size, 2000)
    iy = rng.integers(0, y.size, 2000)
    sample = np.abs((fx[ix] * gy[iy]).sum(1) - np.exp(-((x[ix] - y[iy]) ** 2) / sigma2)).max()
    return SeparableAffinity(node, F, G, max_error=2.0 * max(err, sample))


def _scatter_factors(values: np.ndarray, M: np.ndarray) -> np.ndarray:
    """(R, n, n) factors holding ``values[:, r]`` at the edges ``M`` and 0 elsewhere."""
    n = M.shape[0]
    flat = np.zeros((n * n, values.shape[1]))
    flat[np.flatnonzero(M)] = values
    return np.ascontiguousarray(flat.T).reshape(values.shape[1], n, n)


# --------------------------------------------------------------------------- per-graph factors


def _common_attribute(graphs, attribute):
    if attribute is not None:
        return attribute
    if all(g.edge_features is not None for g in graphs):
        return "features"
    if all(g.points is not None for g in graphs):
        return "length"
    if all(g.edge_features is None and g.points is None for g in graphs):
        return "weight"
    return None     # mixed: the per-pair default differs between pairs


@dataclass(frozen=True)
class GaussianEdgeFactors:
    """Per-graph factors of the Gaussian edge kernel (see :func:`gaussian_edge_factors`).

    Parameters
    ----------
    F, G : ndarray of shape (N, R, n, n)
        Factors of the ``N`` graphs: ``K_ij ~= sum_r F[i, r] (x) G[j, r]``.
    max_error : float
        Entrywise error of the expansion against the exact kernel.
    attributes : ndarray of shape (N, n, n)
        The graphs' scalar edge attributes (0 off the edges).
    masks : ndarray of shape (N, n, n)
        The graphs' edge masks.
    sigma2 : float
        Kernel width.
    attribute : str
        The edge attribute used (``"length"``, ``"weight"`` or ``"features"``).

    Examples
    --------
    >>> import numpy as np
    >>> from transync.graphs import Graph
    >>> from transync.matching import gaussian_edge_factors
    >>> rng = np.random.default_rng(0)
    >>> gs = [Graph.from_points(rng.random((4, 2)), edges="full") for _ in range(2)]
    >>> fac = gaussian_edge_factors(gs)
    >>> fac.F.shape[0], fac.F.shape[2:], fac.attribute, bool(fac.max_error < 1e-8)
    (2, (4, 4), 'length', True)
    """

    F: np.ndarray
    G: np.ndarray
    max_error: float
    attributes: np.ndarray
    masks: np.ndarray
    sigma2: float
    attribute: str

    @property
    def rank(self) -> int:
        return int(self.F.shape[1])


def gaussian_edge_factors(graphs, *, sigma2: float = DEFAULT_SIGMA2, attribute: str | None = None,
                          tol: float = 1e-10, pairs=None) -> GaussianEdgeFactors:
    """Per-graph separable factors of :func:`~transync.matching.gaussian_edge_affinity`.

    One tensor-Chebyshev expansion ``exp(-(x - y)^2 / sigma2) ~= sum_r a_r(x) b_r(y)`` over the
    union of the edge attributes of all graphs (the same construction as the pairwise separable
    backend, on the common range), so that for every pair ``(i, j)``
    ``K_ij ~= sum_r F[i, r] (x) G[j, r]`` (``F[i, r][u, v] = a_r(e_i(u, v))`` on the edges of
    graph ``i``, 0 elsewhere). Entrywise error against the exact kernel: ``max_error``.

    Parameters
    ----------
    graphs : sequence of Graph
        Graphs with the same number of nodes (a list or tuple).
    sigma2, attribute, tol
        As in :func:`~transync.matching.gaussian_edge_affinity` (scalar attributes only:
        ``"length"``, ``"weight"``, ``"features"``).
    pairs : (P, 2) int array, optional
        Pairs whose affinity must not underflow (checked as the pairwise function does, raising
        :class:`~transync.exceptions.DegenerateInputError`); default all pairs.

    Returns
    -------
    GaussianEdgeFactors
        ``F``, ``G`` of shape ``(N, R, n, n)``, ``max_error``, and the graphs' edge
        ``attributes`` and ``masks`` ``(N, n, n)`` (for exact evaluation of the kernel).

    Examples
    --------
    >>> import numpy as np
    >>> from transync.graphs import Graph
    >>> from transync.matching import gaussian_edge_affinity, gaussian_edge_factors
    >>> rng = np.random.default_rng(0)
    >>> gs = [Graph.from_points(rng.random((5, 2)), edges="full") for _ in range(3)]
    >>> fac = gaussian_edge_factors(gs, sigma2=0.05)
    >>> K = np.einsum("rij,rab->aibj", fac.F[0], fac.G[2]).reshape(25, 25)
    >>> bool(np.abs(K - gaussian_edge_affinity(gs[0], gs[2], sigma2=0.05).to_dense()).max() < 1e-8)
    True
    """
    sigma2 = check_positive(sigma2, "sigma2")
    tol = check_positive(tol, "tol")
    if isinstance(graphs, Graph) or not isinstance(graphs, (list, tuple)) or not graphs:
        raise TypeError("`graphs` must be a non-empty list or tuple of Graph, got "
                        f"{type(graphs).__name__}")
    for k, g in enumerate(graphs):
        if not isinstance(g, Graph):
            raise TypeError(f"`graphs[{k}]` must be a Graph, got {type(g).__name__}")
    attribute = _common_attribute(graphs, attribute)
    if attribute is None:
        raise ValueError("the graphs disagree on their edge attributes (some have edge_features "
                         "or points, others not): pass `attribute`")
    check_choice(attribute, "attribute", ("length", "weight", "features"))
    attrs = [_edge_attributes(g, attribute, f"graphs[{k}]")[0] for k, g in enumerate(graphs)]
    masks = [g.mask for g in graphs]
    vals = [a[m] for a, m in zip(attrs, masks)]
    N = len(graphs)
    sizes = {g.n_nodes for g in graphs}
    if len(sizes) != 1:
        raise ValueError(f"`graphs` must all have the same number of nodes, got sizes "
                         f"{sorted(sizes)}")
    n = sizes.pop()
    if pairs is None:
        pairs = np.stack(np.triu_indices(N, 1), axis=1)
    else:
        pairs = check_index_pairs(pairs, N, what="graph indices")
    if attribute == "length":           # as gaussian_edge_affinity refuses for every pair
        dim = np.array([-1 if g.points is None else g.points.shape[1] for g in graphs])
        bad = np.flatnonzero((dim[pairs[:, 0]] != dim[pairs[:, 1]])
                             & (dim[pairs[:, 0]] >= 0) & (dim[pairs[:, 1]] >= 0))
        if bad.size:
            i, j = (int(x) for x in pairs[bad[0]])
            raise ValueError(f"`graphs[{i}]` and `graphs[{j}]` must have points of the same "
                             f"dimension for attribute='length', got {dim[i]} and {dim[j]}")
    nonempty = [v for v in vals if v.size]
    E = np.stack([np.where(m, a, 0.0) for a, m in zip(attrs, masks)])
    M = np.stack(masks)
    if not nonempty:
        return GaussianEdgeFactors(np.zeros((N, 1, n, n)), np.zeros((N, 1, n, n)), 0.0, E, M,
                                   sigma2, attribute)
    _check_underflow(vals, pairs, sigma2, attribute)
    lo, hi = _interpolation_interval(float(min(v.min() for v in nonempty)),
                                     float(max(v.max() for v in nonempty)), sigma2)
    span = hi - lo
    p = int(np.clip(np.ceil(8 + 4.0 * span / np.sqrt(sigma2)), 12, 200))
    c = _chebyshev_nodes(lo, hi, p)
    C = np.exp(-((c[:, None] - c[None, :]) ** 2) / sigma2)
    U, s, Vt = _small_svd(C)
    R = int(np.searchsorted(-s, -tol * 0.1)) or 1
    R = max(1, min(R, p))
    A = U[:, :R] * np.sqrt(s[:R])
    B = Vt[:R].T * np.sqrt(s[:R])
    F = np.empty((N, R, n, n))
    G = np.empty((N, R, n, n))
    for k, (v, m) in enumerate(zip(vals, masks)):
        basis = _lagrange_basis(v, c)
        F[k] = _scatter_factors(basis @ A, m)
        G[k] = _scatter_factors(basis @ B, m)
    grid = np.linspace(lo, hi, 129)
    Lg = _lagrange_basis(grid, c)
    approx = (Lg @ A) @ (Lg @ B).T
    err = float(np.abs(approx - np.exp(-((grid[:, None] - grid[None, :]) ** 2) / sigma2)).max())
    allv = np.concatenate(nonempty)
    rng = np.random.default_rng(0)
    ix, iy = rng.integers(0, allv.size, 2000), rng.integers(0, allv.size, 2000)
    La, Lb = _lagrange_basis(allv[ix], c) @ A, _lagrange_basis(allv[iy], c) @ B
    sample = float(np.abs((La * Lb).sum(1)
                          - np.exp(-((allv[ix] - allv[iy]) ** 2) / sigma2)).max())
    return GaussianEdgeFactors(F, G, 2.0 * max(err, sample), E, M, sigma2, attribute)


def _check_underflow(vals, pairs, sigma2, attribute):
    """The pairwise function's refusal of a vanishing kernel, for every pair."""
    radius = np.sqrt(_UNDERFLOW * sigma2)
    nonempty = [v for v in vals if v.size]
    lo = min(v.min() for v in nonempty)
    hi = max(v.max() for v in nonempty)
    if hi - lo <= radius:
        return                                  # every attribute pair is within the radius
    sorted_vals = [np.sort(v) for v in vals]
    for i, j in pairs:
        x, y = sorted_vals[i], vals[j]
        if x.size and y.size:
            _refuse_underflow(_count_close(x, y, radius), min(x.size, y.size), sigma2,
                              f"edge attributes ({attribute!r})",
                              float(np.median(np.abs(np.concatenate([x, y])))))
