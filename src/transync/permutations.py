"""Assignments (partial permutations) as index arrays, and the converters around them.

A pairwise matching between an object with ``n1`` nodes and one with ``n2`` nodes is an int
array ``assignment`` of length ``n1``: ``assignment[u] = v`` maps node ``u`` to node ``v``
and ``-1`` marks an unmatched node. The matching matrix is ``X[u, v] = 1`` iff
``assignment[u] == v``. Matrices appear only through the converters here.

Examples
--------
>>> import numpy as np
>>> from transync.permutations import compose, invert, assignment_to_matrix
>>> a = np.array([2, 0, -1])           # 3 nodes into 3 nodes, node 2 unmatched
>>> invert(a, n2=3)
array([ 1, -1,  0])
>>> compose(a, np.array([1, 2, 0]))    # follow a, then a second map
array([ 0,  1, -1])
>>> assignment_to_matrix(a, n2=3).astype(int)
array([[0, 0, 1],
       [1, 0, 0],
       [0, 0, 0]])
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np
from scipy.optimize import linear_sum_assignment

from ._validation import as_generator, check_array, check_int

__all__ = [
    "UNMATCHED",
    "assignment_to_matrix",
    "check_assignment",
    "compose",
    "cycle_inconsistency",
    "identity",
    "invert",
    "is_partial_permutation_matrix",
    "matrix_to_assignment",
    "random_permutation",
    "solve_lap",
]

UNMATCHED = -1


def check_assignment(assignment, name: str = "assignment", *, n2: int | None = None,
                     n1: int | None = None) -> np.ndarray:
    """Validate an assignment index array and return it as ``int64``.

    Raises ``ValueError`` when values fall outside ``[-1, n2)`` or a target is used twice.
    """
    arr = np.asarray(assignment)
    if arr.ndim != 1:
        raise ValueError(f"`{name}` must be a 1-d index array, got shape {arr.shape}")
    if arr.size and arr.dtype.kind not in "iu":
        if arr.dtype.kind == "f" and np.all(np.isfinite(arr)) and np.all(arr == np.round(arr)):
            arr = arr.astype(np.int64)
        else:
            raise TypeError(f"`{name}` must hold integers, got dtype {arr.dtype}")
    arr = arr.astype(np.int64, copy=False)
    if n1 is not None and arr.shape[0] != n1:
        raise ValueError(f"`{name}` must have length {n1}, got length {arr.shape[0]}")
    if arr.size and arr.min() < UNMATCHED:
        raise ValueError(f"`{name}` entries must be >= -1, got {int(arr.min())}")
    if n2 is not None and arr.size and arr.max() >= n2:
        raise ValueError(f"`{name}` entries must be < n2={n2}, got {int(arr.max())}")
    matched = arr[arr >= 0]
    if np.unique(matched).size != matched.size:
        raise ValueError(f"`{name}` must be injective: some target node is used twice")
    return arr


def identity(n: int) -> np.ndarray:
    """The identity assignment of ``n`` nodes."""
    return np.arange(check_int(n, "n", minimum=0), dtype=np.int64)


def random_permutation(n: int, rng=None) -> np.ndarray:
    """A uniformly random permutation of ``n`` nodes as an assignment."""
    return as_generator(rng).permutation(check_int(n, "n", minimum=0)).astype(np.int64)


def assignment_to_matrix(assignment, n2: int, *, dtype=float) -> np.ndarray:
    """Matching matrix ``X`` of shape ``(n1, n2)`` with ``X[u, assignment[u]] = 1``."""
    a = check_assignment(assignment, n2=n2)
    X = np.zeros((a.shape[0], n2), dtype=dtype)
    rows = np.flatnonzero(a >= 0)
    X[rows, a[rows]] = 1
    return X


def is_partial_permutation_matrix(X, *, atol: float = 1e-8) -> bool:
    """True when ``X`` is 0/1 (to ``atol``) with at most one 1 per row and per column."""
    X = np.asarray(X, dtype=float)
    if X.ndim != 2:
        return False
    binary = np.all((np.abs(X) <= atol) | (np.abs(X - 1) <= atol))
    return bool(binary and np.all(X.sum(0) <= 1 + atol) and np.all(X.sum(1) <= 1 + atol))


def matrix_to_assignment(X, *, name: str = "X") -> np.ndarray:
    """Assignment from a 0/1 partial-permutation matrix (rows without a 1 become -1)."""
    X = check_array(X, name, ndim=2)
    if not is_partial_permutation_matrix(X):
        raise ValueError(f"`{name}` must be a 0/1 matrix with at most one 1 per row and column; "
                         "round soft matrices with `solve_lap` first")
    a = np.full(X.shape[0], UNMATCHED, dtype=np.int64)
    rows, cols = np.nonzero(X > 0.5)
    a[rows] = cols
    return a


def invert(assignment, n2: int) -> np.ndarray:
    """Inverse map: ``b[v] = u`` where ``assignment[u] = v``, ``-1`` for unused targets."""
    a = check_assignment(assignment, n2=n2)
    b = np.full(n2, UNMATCHED, dtype=np.int64)
    rows = np.flatnonzero(a >= 0)
    b[a[rows]] = rows
    return b


def compose(first, second) -> np.ndarray:
    """Follow ``first`` (i -> j) then ``second`` (j -> k); unmatched anywhere gives -1."""
    a = check_assignment(first, "first")
    b = check_assignment(second, "second")
    if a.size and a.max() >= b.shape[0]:
        raise ValueError(f"`first` maps into {int(a.max()) + 1} or more nodes but `second` "
                         f"has length {b.shape[0]}")
    out = np.full(a.shape[0], UNMATCHED, dtype=np.int64)
    ok = a >= 0
    out[ok] = b[a[ok]]
    return out


def solve_lap(score, *, maximize: bool = True, min_score: float | None = None,
              name: str = "score") -> np.ndarray:
    """Rectangular linear assignment on ``score`` of shape ``(n1, n2)`` (Hungarian, via SciPy).

    Returns an assignment of length ``n1``; when ``n1 > n2`` the rows left over are ``-1``.
    With ``min_score`` (maximizing) pairs whose score is below it are dropped to ``-1``.

    >>> solve_lap(np.array([[0.1, 0.9], [0.8, 0.2], [0.0, 0.1]]))
    array([ 1,  0, -1])
    """
    S = check_array(score, name, ndim=2)
    rows, cols = linear_sum_assignment(S, maximize=maximize)
    a = np.full(S.shape[0], UNMATCHED, dtype=np.int64)
    a[rows] = cols
    if min_score is not None:
        keep = S[rows, cols] >= min_score if maximize else S[rows, cols] <= min_score
        a[rows[~keep]] = UNMATCHED
    return a


def cycle_inconsistency(pairwise: Mapping[tuple[int, int], np.ndarray], *,
                        max_triangles: int = 200_000, rng=None) -> dict[str, float]:
    """How far a collection of pairwise assignments is from cycle consistency.

    ``pairwise[(i, j)]`` maps the nodes of object ``i`` into object ``j``. For every triangle
    ``i < j < k`` with all three pairs observed (either direction; a missing direction is the
    inverse of the given one, ``(i, j)`` wins when both are given), the composition
    ``i -> j -> k`` is compared with ``i -> k``. Returns the number of triangles checked, the
    fraction of inconsistent ones and the mean fraction of disagreeing nodes (``cycle_error``).

    When there are more than ``max_triangles`` candidate triples, ``max_triangles`` triples
    ``i < j < k`` are drawn uniformly at random (with ``rng``) and the observed ones among them
    are checked; ``"sampled"`` says so. The work is vectorized over triangles (index gathers).

    >>> p = {(0, 1): np.array([1, 0]), (1, 2): np.array([1, 0]), (0, 2): np.array([0, 1])}
    >>> cycle_inconsistency(p)
    {'n_triangles': 1, 'inconsistent_triangles': 0.0, 'cycle_error': 0.0, 'sampled': False}
    """
    if not isinstance(pairwise, Mapping):
        raise TypeError(f"`pairwise` must be a dict {{(i, j): assignment}}, got "
                        f"{type(pairwise).__name__}")
    check_int(max_triangles, "max_triangles", minimum=1)
    arrays: dict[tuple[int, int], np.ndarray] = {}
    sizes: dict[int, int] = {}
    for (i, j), a in pairwise.items():
        i, j = int(i), int(j)
        a = check_assignment(a, f"pairwise[{(i, j)}]")
        arrays[(i, j)] = a
        sizes[i] = max(sizes.get(i, 0), a.shape[0])
        if a.size:
            sizes[j] = max(sizes.get(j, 0), int(a.max()) + 1)
    if not arrays:
        return {"n_triangles": 0, "inconsistent_triangles": 0.0, "cycle_error": 0.0,
                "sampled": False}
    n_obj = max(sizes) + 1
    size_arr = np.zeros(n_obj, dtype=np.int64)
    for g, n in sizes.items():
        size_arr[g] = n
    n_max = int(size_arr.max())
    canon: dict[tuple[int, int], np.ndarray] = {}
    for (i, j), a in arrays.items():
        if i < j:
            canon[(i, j)] = a
    for (i, j), a in arrays.items():
        if i > j and (j, i) not in canon:
            canon[(j, i)] = invert(a, int(size_arr[i]))
    pairs = np.array(list(canon.keys()), dtype=np.int64).reshape(-1, 2)
    maps = np.full((len(canon), n_max), UNMATCHED, dtype=np.int64)
    for q, a in enumerate(canon.values()):
        maps[q, : a.shape[0]] = a
    return _triangle_report(pairs, maps, size_arr, max_triangles=max_triangles, rng=rng)


def _triangle_report(pairs: np.ndarray, maps: np.ndarray, sizes: np.ndarray, *,
                     max_triangles: int = 200_000, rng=None) -> dict[str, float]:
    """Vectorized triangle check on stacked maps (private; pairs oriented ``i < j``).

    ``maps[q]`` is the assignment ``pairs[q, 0] -> pairs[q, 1]`` padded with -1 to a common
    width. Duplicate pairs: the first occurrence is used.
    """
    n_obj = int(sizes.shape[0])
    n_max = maps.shape[1]
    pid = np.full((n_obj, n_obj), -1, dtype=np.int64)
    q_rev = np.arange(pairs.shape[0])[::-1]
    pid[pairs[q_rev, 0], pairs[q_rev, 1]] = q_rev          # first occurrence wins
    # a column of -1 so that "unmatched" indexes to unmatched: ajk_pad[-1] = -1
    maps_pad = np.concatenate([maps, np.full((maps.shape[0], 1), UNMATCHED, maps.dtype)], 1)
    total = n_obj * (n_obj - 1) * (n_obj - 2) // 6
    sampled = total > max_triangles

    def _chunks():
        if sampled:
            gen = as_generator(rng)
            left = max_triangles
            while left > 0:
                m = min(left, 100_000)
                tri = np.sort(np.column_stack([gen.integers(0, n_obj, 3 * m) for _ in range(3)])
                              .reshape(-1, 3)[:m * 3], axis=1)
                tri = tri[(tri[:, 0] < tri[:, 1]) & (tri[:, 1] < tri[:, 2])][:m]
                left -= m
                yield tri
        else:
            for i in range(n_obj - 2):
                row = pid[i]
                js = np.flatnonzero(row[i + 1:] >= 0) + i + 1
                if js.size < 2:
                    continue
                jj, kk = np.triu_indices(js.size, 1)
                yield np.column_stack([np.full(jj.size, i), js[jj], js[kk]])

    n_tri = 0
    bad = 0
    err = 0.0
    for tri in _chunks():
        qij = pid[tri[:, 0], tri[:, 1]]
        qjk = pid[tri[:, 1], tri[:, 2]]
        qik = pid[tri[:, 0], tri[:, 2]]
        ok = (qij >= 0) & (qjk >= 0) & (qik >= 0)
        if not ok.any():
            continue
        qij, qjk, qik, tri = qij[ok], qjk[ok], qik[ok], tri[ok]
        aij = maps[qij]                                       # (t, n_max)
        via = np.take_along_axis(maps_pad[qjk], np.where(aij >= 0, aij, n_max), axis=1)
        diff = (via != maps[qik]).sum(1)                      # padding is -1 on both sides
        n_tri += int(tri.shape[0])
        bad += int(np.count_nonzero(diff))
        err += float((diff / np.maximum(sizes[tri[:, 0]], 1)).sum())
    return {
        "n_triangles": n_tri,
        "inconsistent_triangles": float(bad / n_tri) if n_tri else 0.0,
        "cycle_error": float(err / n_tri) if n_tri else 0.0,
        "sampled": bool(sampled),
    }
