"""Assignments (partial permutations) as index arrays, and the converters around them.

A pairwise matching between an object with ``n1`` nodes and one with ``n2`` nodes is an int
array ``assignment`` of length ``n1``: ``assignment[u] = v`` maps node ``u`` to node ``v``
and ``-1`` marks an unmatched node. The matching matrix is ``X[u, v] = 1`` iff
``assignment[u] == v``. Matrices appear only through the converters here.

A multi-matching of many objects is a :class:`MultiMatching`: universe labels per object, from
which every pairwise map is derived (cycle-consistent by construction); it is the only place
where labels become pairwise maps.

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

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import linear_sum_assignment

from ._validation import (
    as_generator,
    check_array,
    check_bool,
    check_index_pairs,
    check_int,
    check_int_array,
    check_positive,
    check_real,
)

__all__ = [
    "MAX_NODES",
    "UNMATCHED",
    "MultiMatching",
    "assignment_to_matrix",
    "check_assignment",
    "compose",
    "cycle_inconsistency",
    "cycle_inconsistency_arrays",
    "first_invalid_assignment",
    "identity",
    "invert",
    "is_partial_permutation_matrix",
    "matrix_to_assignment",
    "pair_rows",
    "random_permutation",
    "solve_lap",
]

UNMATCHED = -1
MAX_NODES = 10**8      # largest object (and dense matching matrix) the converters build
_MAX_MATRIX_SIDE = 20000   # largest MultiMatching.to_matrix() whatever max_size (3.2 GB)
_MAX_TRIANGLES = 10**8  # most triangles cycle_inconsistency checks (10**9 ran for hours)
#: candidate triples listed in full (every triangle found, then subsampled to max_triangles);
#: above, candidates are drawn, this many at most
_CANDIDATE_LIMIT = 4_000_000


def first_invalid_assignment(flat, lengths) -> int | None:
    """Many int assignments validated at once: the index of the first invalid one.

    ``flat`` is the concatenation of the assignments, ``lengths`` their lengths. An assignment
    is invalid with an entry below ``-1`` or at least ``2**62``, or a target used twice (what
    :func:`check_assignment` refuses besides the target range, which depends on the other
    object; call it on the one returned for its message). One sort for all of them: ENZYMES'
    179 700 real-node maps in under a second instead of 8 s one by one.

    Parameters
    ----------
    flat : ndarray of int64
        The entries of every assignment, one after the other.
    lengths : ndarray of int64
        The length of every assignment (they sum to ``len(flat)``).

    Returns
    -------
    int or None
        -1 when all are valid; the index of the first invalid assignment; None when the
        entries are too large to share one sort key (then check them one by one).

    Examples
    --------
    >>> first_invalid_assignment(np.array([1, 0, 0, -1, 2, 2]), np.array([2, 2, 2]))
    2
    >>> first_invalid_assignment(np.array([1, 0, -1]), np.array([2, 1]))
    -1

    Raises
    ------
    TypeError, ValueError
        ``flat`` or ``lengths`` not a 1-d integer array, negative lengths, or lengths that do
        not sum to ``len(flat)``.
    """
    flat = check_int_array(flat, "flat", ndim=1)
    lengths = check_int_array(lengths, "lengths", ndim=1)
    if lengths.size and int(lengths.min()) < 0:
        raise ValueError(f"`lengths` must be non-negative, got {int(lengths.min())}")
    if int(lengths.sum()) != flat.size:
        raise ValueError(f"`lengths` must sum to len(flat) = {flat.size}, got "
                         f"{int(lengths.sum())}")
    n = len(lengths)
    row = np.repeat(np.arange(n), lengths)
    out_of_range = (flat < UNMATCHED) | (flat >= 2**62)
    bad = np.zeros(n, dtype=bool)
    bad[row[out_of_range]] = True
    used = np.flatnonzero((flat >= 0) & ~out_of_range)
    top = int(flat[used].max()) + 1 if used.size else 1
    if top >= 2**62 // max(n, 1):
        return None
    key = np.sort(row[used] * top + flat[used])
    bad[key[1:][key[1:] == key[:-1]] // top] = True           # a target used twice
    return int(np.flatnonzero(bad)[0]) if bad.any() else -1


def pair_rows(pairs, n_objects: int):
    """A lookup ``rows(a, b)`` of the row of the unordered pair ``{a, b}`` in ``pairs``.

    Built from sorted keys ``min * N + max`` and a binary search: no ``(N, N)`` table, whatever
    the object indices (up to ``2**31`` objects). On duplicate rows the first wins; a pair not in
    ``pairs`` gives ``-1``.

    Parameters
    ----------
    pairs : array_like of shape (Q, 2), int
        Pairs of object indices in ``[0, n_objects)``.
    n_objects : int
        Number of objects ``N``.

    Returns
    -------
    callable
        ``rows(a, b)`` for int arrays ``a``, ``b`` of one shape: the rows, ``-1`` where absent
        (indices outside ``[0, N)`` included); non-integer queries raise ``TypeError``.

    Examples
    --------
    >>> rows = pair_rows(np.array([[0, 1], [2, 1], [0, 1]]), 3)
    >>> rows(np.array([1, 1, 0]), np.array([0, 2, 2])).tolist()
    [0, 1, -1]
    """
    n_objects = check_int(n_objects, "n_objects", minimum=0, maximum=2**31)
    pairs = check_int_array(pairs, "pairs", ndim=2, integral_floats=True,
                            what="integer object indices")
    if pairs.size == 0:
        pairs = pairs.reshape(0, 2)
    if pairs.shape[1] != 2:
        raise ValueError(f"`pairs` must have shape (Q, 2), got {pairs.shape}")
    if pairs.size and (pairs.min() < 0 or pairs.max() >= n_objects):
        raise ValueError(f"`pairs` must hold object indices in [0, {n_objects}) (keys of "
                         f"larger indices collide), got range [{int(pairs.min())}, "
                         f"{int(pairs.max())}]")
    n = np.int64(n_objects)
    keys, first = np.unique(pairs.min(1) * n + pairs.max(1), return_index=True)

    def rows(a, b) -> np.ndarray:
        a, b = np.asarray(a), np.asarray(b)
        if a.dtype.kind not in "iu" or b.dtype.kind not in "iu":   # 1.9 was read as 1
            raise TypeError(f"pair_rows: the queries must be integer arrays, got dtypes "
                            f"{a.dtype} and {b.dtype}")
        a, b = a.astype(np.int64), b.astype(np.int64)
        k = np.minimum(a, b) * n + np.maximum(a, b)
        if not keys.size:
            return np.full(k.shape, -1, dtype=np.int64)
        pos = np.minimum(np.searchsorted(keys, k), keys.size - 1)
        # an index outside [0, N) has a key of another pair: absent, not that pair's row
        inside = (np.minimum(a, b) >= 0) & (np.maximum(a, b) < n)
        return np.where((keys[pos] == k) & inside, first[pos], -1)

    return rows


def _as_label_array(lab, name: str) -> np.ndarray:
    """A 1-d int64 copy of an index array; integral floats are accepted, NaN, fractions,
    strings, complex and other dtypes refused with a message naming ``name``."""
    if lab is None or isinstance(lab, (str, bytes)):
        raise TypeError(f"`{name}` must be a 1-d integer index array, got {type(lab).__name__}")
    try:
        arr = np.asarray(lab)
    except (TypeError, ValueError):                # ragged nesting
        raise TypeError(f"`{name}` must be a 1-d integer index array, got a ragged "
                        "sequence") from None
    if arr.ndim != 1:
        raise ValueError(f"`{name}` must be a 1-d index array, got shape {arr.shape}")
    kind = arr.dtype.kind
    try:
        arr = check_int_array(arr, name, integral_floats=True, copy=True,
                              what="integers (node indices, -1 = unmatched)")
    except ValueError:                         # integers beyond int64: no node indices either
        top = arr.flat[np.argmax(np.abs(arr))].item()
        raise ValueError(f"`{name}` entries must be node indices, got {top!r}") from None
    if kind in "uf" and arr.size:              # float and unsigned input: bounded as ever
        lo, hi = int(arr.min()), int(arr.max())
        if hi >= 2**62 or (kind == "f" and lo <= -(2**62)):
            raise ValueError(f"`{name}` entries must be node indices, got "
                             f"{hi if hi >= 2**62 else lo}")
    return arr


def check_assignment(assignment, name: str = "assignment", *, n2: int | None = None,
                     n1: int | None = None) -> np.ndarray:
    """Validate an assignment index array and return it as ``int64``.

    Parameters
    ----------
    assignment : array_like of shape (n1,), int
        ``assignment[u] = v`` maps node ``u`` to node ``v``; ``-1`` marks an unmatched node.
        Integral floats are accepted.
    name : str, default="assignment"
        Argument name used in error messages.
    n2 : int, optional
        Size of the target object; entries must then be ``< n2``.
    n1 : int, optional
        Required length of ``assignment``.

    Returns
    -------
    ndarray of shape (n1,), int64
        A validated copy.

    Raises
    ------
    TypeError
        Non-integer entries (fractions, NaN, strings, complex).
    ValueError
        Not 1-d, wrong length, entries outside ``[-1, n2)``, or a target used twice.

    Examples
    --------
    >>> check_assignment([2.0, 0, -1], n2=3)
    array([ 2,  0, -1])
    """
    arr = _as_label_array(assignment, name)
    n1 = None if n1 is None else check_int(n1, "n1", minimum=0)
    n2 = None if n2 is None else check_int(n2, "n2", minimum=0)
    if arr.size and arr.max() >= 2**62:
        raise ValueError(f"`{name}` entries must be node indices, got {int(arr.max())}")
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
    """The identity assignment of ``n`` nodes.

    Parameters
    ----------
    n : int
        Number of nodes (>= 0).

    Returns
    -------
    ndarray of shape (n,), int64
        ``arange(n)``.

    Raises
    ------
    ValueError, TypeError
        ``n`` negative, too large (above :data:`MAX_NODES`) or not an integer.

    Examples
    --------
    >>> identity(3)
    array([0, 1, 2])
    """
    return np.arange(check_int(n, "n", minimum=0, maximum=MAX_NODES), dtype=np.int64)


def random_permutation(n: int, rng=None) -> np.ndarray:
    """A uniformly random permutation of ``n`` nodes as an assignment.

    Parameters
    ----------
    n : int
        Number of nodes (>= 0).
    rng : None, int or numpy.random.Generator, optional
        Source of randomness.

    Returns
    -------
    ndarray of shape (n,), int64
        A permutation of ``0 .. n - 1``.

    Raises
    ------
    ValueError, TypeError
        ``n`` negative, too large or not an integer; an invalid ``rng``.

    Examples
    --------
    >>> sorted(random_permutation(4, rng=0).tolist())
    [0, 1, 2, 3]
    """
    n = check_int(n, "n", minimum=0, maximum=MAX_NODES)
    return as_generator(rng).permutation(n).astype(np.int64)


def assignment_to_matrix(assignment, n2: int, *, dtype=float) -> np.ndarray:
    """Matching matrix ``X`` of shape ``(n1, n2)`` with ``X[u, assignment[u]] = 1``.

    Parameters
    ----------
    assignment : array_like of shape (n1,), int
        Assignment (``-1``: unmatched, an all-zero row).
    n2 : int
        Number of columns (nodes of the target object).
    dtype : data-type, default=float
        Data type of the matrix.

    Returns
    -------
    ndarray of shape (n1, n2)
        The 0/1 partial-permutation matrix.

    Raises
    ------
    ValueError, TypeError
        An invalid assignment (see :func:`check_assignment`), or a matrix of more than
        :data:`MAX_NODES` entries.

    Examples
    --------
    >>> assignment_to_matrix([1, -1], 2).astype(int)
    array([[0, 1],
           [0, 0]])
    """
    n2 = check_int(n2, "n2", minimum=0, maximum=MAX_NODES)
    try:
        dtype = np.dtype(dtype)
    except TypeError:
        raise TypeError(f"`dtype` must be a numpy data type, got {dtype!r}") from None
    a = check_assignment(assignment, n2=n2)
    if a.shape[0] * n2 > MAX_NODES:
        raise ValueError(f"`assignment` of length {a.shape[0]} and n2={n2} would build a matrix "
                         f"of {a.shape[0] * n2:.3g} entries (more than {MAX_NODES:.0e})")
    X = np.zeros((a.shape[0], n2), dtype=dtype)
    rows = np.flatnonzero(a >= 0)
    X[rows, a[rows]] = 1
    return X


def is_partial_permutation_matrix(X, *, atol: float = 1e-8) -> bool:
    """True when ``X`` is 0/1 (to ``atol``) with at most one 1 per row and per column.

    A predicate: any real array answers (non-2-D arrays and NaN entries answer False).

    Parameters
    ----------
    X : array_like
        The matrix to test.
    atol : float, default=1e-8
        Tolerance on the 0/1 entries and on the row and column sums.

    Returns
    -------
    bool
        Whether every entry is 0 or 1 with at most one 1 in each row and column.

    Raises
    ------
    TypeError
        Complex or non-numeric input.

    Examples
    --------
    >>> is_partial_permutation_matrix([[0, 1], [0, 0]]), is_partial_permutation_matrix([[1, 1]])
    (True, False)
    """
    X = check_array(X, "X", finite=False)
    atol = check_positive(atol, "atol", allow_zero=True)
    if atol >= 0.5:             # 0 and 1 would overlap: 0.5 everywhere would pass
        raise ValueError(f"`atol` must be < 0.5 (a tolerance on 0/1 entries), got {atol!r}")
    if X.ndim != 2:
        return False
    binary = np.all((np.abs(X) <= atol) | (np.abs(X - 1) <= atol))
    return bool(binary and np.all(X.sum(0) <= 1 + atol) and np.all(X.sum(1) <= 1 + atol))


def matrix_to_assignment(X, *, name: str = "X") -> np.ndarray:
    """Assignment from a 0/1 partial-permutation matrix (rows without a 1 become -1).

    Parameters
    ----------
    X : array_like of shape (n1, n2)
        0/1 matrix with at most one 1 per row and per column.
    name : str, default="X"
        Argument name used in error messages.

    Returns
    -------
    ndarray of shape (n1,), int64
        ``assignment[u] = v`` where ``X[u, v] = 1``, else ``-1``.

    Raises
    ------
    ValueError
        ``X`` is not a partial-permutation matrix (round soft matrices with :func:`solve_lap`).

    Examples
    --------
    >>> matrix_to_assignment([[0, 1], [0, 0]])
    array([ 1, -1])
    """
    X = check_array(X, name, ndim=2)
    if not is_partial_permutation_matrix(X):
        raise ValueError(f"`{name}` must be a 0/1 partial-permutation matrix (at most one 1 per "
                         "row and column); round soft matrices with `solve_lap` first")
    a = np.full(X.shape[0], UNMATCHED, dtype=np.int64)
    rows, cols = np.nonzero(X > 0.5)
    a[rows] = cols
    return a


def invert(assignment, n2: int) -> np.ndarray:
    """Inverse map: ``b[v] = u`` where ``assignment[u] = v``, ``-1`` for unused targets.

    Parameters
    ----------
    assignment : array_like of shape (n1,), int
        Assignment into an object of ``n2`` nodes.
    n2 : int
        Number of nodes of the target object (the length of the result).

    Returns
    -------
    ndarray of shape (n2,), int64
        The inverse assignment.

    Raises
    ------
    ValueError, TypeError
        An invalid assignment or ``n2``.

    Examples
    --------
    >>> invert([2, 0, -1], n2=3)
    array([ 1, -1,  0])
    """
    n2 = check_int(n2, "n2", minimum=0, maximum=MAX_NODES)
    a = check_assignment(assignment, n2=n2)
    b = np.full(n2, UNMATCHED, dtype=np.int64)
    rows = np.flatnonzero(a >= 0)
    b[a[rows]] = rows
    return b


def compose(first, second) -> np.ndarray:
    """Follow ``first`` (i -> j) then ``second`` (j -> k); unmatched anywhere gives -1.

    Parameters
    ----------
    first : array_like of shape (n_i,), int
        Assignment from object ``i`` to object ``j``.
    second : array_like of shape (n_j,), int
        Assignment from object ``j`` to object ``k``.

    Returns
    -------
    ndarray of shape (n_i,), int64
        The composed assignment ``i -> k``.

    Raises
    ------
    ValueError, TypeError
        Invalid assignments, or ``first`` pointing beyond the length of ``second``.

    Examples
    --------
    >>> compose([2, 0, -1], [1, 2, 0])
    array([ 0,  1, -1])
    """
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

    Parameters
    ----------
    score : array_like of shape (n1, n2)
        Finite scores (or costs with ``maximize=False``).
    maximize : bool, default=True
        Maximize the total score (else minimize the total cost).
    min_score : float, optional
        Pairs whose score is below it (above it when minimizing) are dropped to ``-1``.
    name : str, default="score"
        Argument name used in error messages.

    Returns
    -------
    ndarray of shape (n1,), int64
        The assignment; when ``n1 > n2`` the rows left over are ``-1``.

    Raises
    ------
    ValueError, TypeError
        ``score`` not 2-d, not finite or not numeric.

    Examples
    --------
    >>> solve_lap(np.array([[0.1, 0.9], [0.8, 0.2], [0.0, 0.1]]))
    array([ 1,  0, -1])
    """
    S = check_array(score, name, ndim=2)
    maximize = check_bool(maximize, "maximize")
    if min_score is not None:
        min_score = check_real(min_score, "min_score")     # NaN dropped every pair silently
    rows, cols = linear_sum_assignment(S, maximize=maximize)
    a = np.full(S.shape[0], UNMATCHED, dtype=np.int64)
    a[rows] = cols
    if min_score is not None:
        keep = S[rows, cols] >= min_score if maximize else S[rows, cols] <= min_score
        a[rows[~keep]] = UNMATCHED
    return a


def cycle_inconsistency(pairwise: Mapping[tuple[int, int], np.ndarray], *,
                        max_triangles: int = 200_000, rng=None,
                        sizes=None) -> dict[str, float]:
    """How far a collection of pairwise assignments is from cycle consistency.

    ``pairwise[(i, j)]`` maps the nodes of object ``i`` into object ``j``. For every triangle
    ``i < j < k`` with all three pairs observed (either direction; a missing direction is the
    inverse of the given one, ``(i, j)`` wins when both are given), the composition
    ``i -> j -> k`` is compared with ``i -> k``. Returns the number of triangles checked, the
    fraction of inconsistent ones and the mean fraction of disagreeing nodes (``cycle_error``).

    Partial maps (``-1`` = unmatched, objects of different sizes): a node unmatched by the first
    hop constrains nothing, so each triangle is checked in its three orientations (middle object
    ``j``, ``k`` and ``i``: ``X_ij X_jk <= X_ik`` and the like), a node of the source disagreeing
    when its first hop is matched and the composition differs from the direct map (``-1``
    included); the triangle's error is the largest fraction over the orientations. Maps read
    off universe labels are consistent (error 0); for full permutations the three orientations
    count the same nodes, so this is the plain comparison.

    Triangles are found among the candidate triples ``i < j < k`` whose pairs ``(i, j)`` and
    ``(i, k)`` are observed. Up to 4 million candidates are listed and every triangle among
    them is found; when there are more than ``max_triangles`` triangles, a uniform sample of
    ``max_triangles`` of them (with ``rng``) is checked. Above 4 million candidates, candidates
    are drawn uniformly (4 million at most) until ``max_triangles`` triangles are found.
    ``"sampled"`` says whether the triangles checked are a sample; ``n_triangles`` is 0 only
    when no triangle was found. The work is vectorized over triangles (index gathers).

    Parameters
    ----------
    pairwise : dict {(i, j): assignment}
        Observed pairwise assignments.
    max_triangles : int, default=200000
        Most triangles checked (a uniform sample of them beyond).
    rng : None, int or numpy.random.Generator, optional
        Draws the triangles when sampling.
    sizes : sequence of int, optional
        Number of nodes of every object. Without it, an object's size is read off the maps: the
        length of its maps as a source, else its largest target + 1. A partial map given only
        as ``(j, i)`` may leave nodes of ``i`` unseen, and the inverse then drops them; give
        ``sizes`` to count every node.

    Returns
    -------
    dict
        ``n_triangles`` (int), ``inconsistent_triangles`` (fraction), ``cycle_error`` (mean
        fraction of disagreeing nodes) and ``sampled`` (bool).

    Raises
    ------
    TypeError
        ``pairwise`` is not a mapping, or holds non-integer assignments.
    ValueError
        Invalid assignments or ``max_triangles``; maps that give an object two sizes (two
        lengths as a source, or a target beyond its length as a source).

    Examples
    --------
    >>> p = {(0, 1): np.array([1, 0]), (1, 2): np.array([1, 0]), (0, 2): np.array([0, 1])}
    >>> cycle_inconsistency(p)
    {'n_triangles': 1, 'inconsistent_triangles': 0.0, 'cycle_error': 0.0, 'sampled': False}
    """
    if not isinstance(pairwise, Mapping):
        raise TypeError(f"`pairwise` must be a dict {{(i, j): assignment}}, got "
                        f"{type(pairwise).__name__}")
    check_int(max_triangles, "max_triangles", minimum=1, maximum=_MAX_TRIANGLES)
    given = None
    if sizes is not None:
        given = check_int_array(sizes, "sizes", ndim=1, integral_floats=True)
        if given.size and given.min() < 0:
            raise ValueError(f"`sizes` must be non-negative node counts, got {given.tolist()}")
    arrays: dict[tuple[int, int], np.ndarray] = {}
    # without `sizes`, the sizes read off the maps (and their evidence, for the messages)
    source: dict[int, tuple[int, tuple[int, int]]] = {}   # object -> (map length, first pair)
    target: dict[int, tuple[int, tuple[int, int]]] = {}   # object -> (largest target, its pair)
    for key, a in pairwise.items():
        if (not isinstance(key, tuple) or len(key) != 2
                or not all(isinstance(k, (int, np.integer)) and not isinstance(k, bool)
                           for k in key) or min(key) < 0 or key[0] == key[1]):
            raise ValueError(f"`pairwise` keys must be pairs (i, j) of distinct non-negative "
                             f"object indices, got {key!r}")
        i, j = int(key[0]), int(key[1])
        if given is not None and not (0 <= i < given.size and 0 <= j < given.size):
            raise ValueError(f"`pairwise` has the pair {(i, j)}, but `sizes` gives "
                             f"{given.size} objects")
        n2 = None if given is None else int(given[j])
        a = check_assignment(a, f"pairwise[{(i, j)}]", n2=n2)
        if given is not None and a.shape[0] != given[i]:
            raise ValueError(f"`pairwise[{(i, j)}]` has {a.shape[0]} entries, but `sizes` "
                             f"gives object {i} {int(given[i])} nodes")
        arrays[(i, j)] = a
        if given is None:
            if i in source and source[i][0] != a.shape[0]:
                raise ValueError(f"`pairwise[{(i, j)}]` has {a.shape[0]} entries, but "
                                 f"`pairwise[{source[i][1]}]` has {source[i][0]}: object {i} "
                                 f"cannot have both sizes")
            source.setdefault(i, (a.shape[0], (i, j)))
            top = int(a.max(initial=-1))
            if top >= 0 and top >= target.get(j, (-1,))[0]:
                target[j] = (top, (i, j))
    for g, (top, key) in target.items():
        if g in source and top >= source[g][0]:
            raise ValueError(f"`pairwise[{key}]` maps a node to node {top} of object {g}, but "
                             f"`pairwise[{source[g][1]}]` gives object {g} {source[g][0]} nodes")
    if not arrays:
        return {"n_triangles": 0, "inconsistent_triangles": 0.0, "cycle_error": 0.0,
                "sampled": False}
    # only the objects in a key take part in a triangle: renumber them 0 .. m - 1 in order
    # (a single key (0, 10**6) built a (10**6, 10**6) pair table)
    objs = sorted({g for key in arrays for g in key})
    rank = {g: r for r, g in enumerate(objs)}
    if given is not None:
        size_arr = given[objs].astype(np.int64)
    else:
        size_arr = np.array([source[g][0] if g in source else target[g][0] + 1
                             if g in target else 0 for g in objs], dtype=np.int64)
    n_max = int(size_arr.max())
    longest = max(a.shape[0] for a in arrays.values())
    if n_max > longest and len(arrays) * n_max > MAX_NODES:
        g = objs[int(np.argmax(size_arr))]      # padding to a size no map has
        why = (f"`sizes` gives object {g} {n_max} nodes" if given is not None else
               f"`pairwise[{target[g][1]}]` maps a node to node {n_max - 1} of object {g}")
        raise ValueError(f"{why}: the {len(arrays)} maps, padded to that width, would need "
                         f"{len(arrays) * n_max:.3g} entries (more than {MAX_NODES:.0e})")
    arrays = {(rank[i], rank[j]): a for (i, j), a in arrays.items()}
    canon: dict[tuple[int, int], np.ndarray] = {}
    for (i, j), a in arrays.items():
        if i < j:
            canon[(i, j)] = a
    for (i, j), a in arrays.items():
        if i > j and (j, i) not in canon:
            canon[(j, i)] = invert(a, int(size_arr[j]))      # a maps i -> j
    pairs = np.array(list(canon.keys()), dtype=np.int64).reshape(-1, 2)
    maps = np.full((len(canon), n_max), UNMATCHED, dtype=np.int64)
    for q, a in enumerate(canon.values()):
        maps[q, : a.shape[0]] = a
    return cycle_inconsistency_arrays(pairs, maps, size_arr, max_triangles=max_triangles, rng=rng)


def _check_map_rows(pairs: np.ndarray, maps: np.ndarray, sizes: np.ndarray) -> None:
    """Every row ``maps[q]`` a valid assignment of ``pairs[q] = (i, j)``: entries past
    ``sizes[i]`` are padding (-1), targets below ``sizes[j]``, no target used twice (as
    :func:`check_assignment` asks of every map of the dict form; a node mapped twice was
    scored)."""
    if not maps.size:
        return
    n_src = np.minimum(sizes[pairs[:, 0]], maps.shape[1])
    real = np.arange(maps.shape[1])[None, :] < n_src[:, None]
    pad = (~real & (maps >= 0)).any(axis=1)
    far = (maps >= sizes[pairs[:, 1]][:, None]).any(axis=1)
    q = first_invalid_assignment(maps[real], n_src)
    if q is None:                       # entries too large for one sort key: row by row
        q = next((r for r, row in enumerate(maps) if (row >= 0).sum() != np.unique(
            row[row >= 0]).size), -1)
    twice = np.arange(len(maps)) == q
    for bad, what in ((pad, "maps a node beyond the size of object {i}"),
                      (far, "targets a node beyond the size of object {j}"),
                      (twice, "uses a target twice (not injective)")):
        rows = np.flatnonzero(bad)
        if rows.size:
            q = int(rows[0])
            i, j = int(pairs[q, 0]), int(pairs[q, 1])
            raise ValueError(f"`maps[{q}]` (pair {(i, j)}) " + what.format(i=i, j=j)
                             + f": {maps[q].tolist()!r:.80}, sizes {int(sizes[i])} and "
                             f"{int(sizes[j])}")


def _triangle_chunks(pairs: np.ndarray, pid, max_triangles: int, gen):
    """The triangles ``(i, j, k)``, ``i < j < k``, of the observed ``pairs`` that
    :func:`cycle_inconsistency_arrays` checks, in chunks, and whether they are a sample
    (see :func:`cycle_inconsistency`); ``pid`` is :func:`pair_rows` of ``pairs``."""
    # candidate triples: (i, j, k), i < j < k, with (i, j) and (i, k) observed -- every
    # triangle is one of them (i its smallest object); drawn among all C(N, 3) triples
    # instead, the triangles of a sparse view graph were almost never hit, and "0 triangles,
    # error 0" read as consistent
    uniq = np.unique(pairs, axis=0)                      # sorted by i, then j
    heads, tails = uniq[:, 0], uniq[:, 1]
    bounds = np.flatnonzero(np.diff(heads)) + 1
    starts, stops = np.r_[0, bounds].astype(np.int64), np.r_[bounds, heads.size].astype(np.int64)
    deg = stops - starts
    per_head = deg * (deg - 1) // 2
    n_cand = int(per_head.sum())
    exhaustive = n_cand <= max(_CANDIDATE_LIMIT, max_triangles)

    def _triangles(tri):
        return tri[pid(tri[:, 1], tri[:, 2]) >= 0]

    def _listed():
        for lo, hi in zip(starts.tolist(), stops.tolist()):
            js = tails[lo:hi]
            if js.size < 2:
                continue
            jj, kk = np.triu_indices(js.size, 1)
            yield np.column_stack([np.full(jj.size, heads[lo]), js[jj], js[kk]])

    def _drawn():
        """Candidates drawn uniformly (a head by its count, then two of its neighbours),
        ``_CANDIDATE_LIMIT`` at most, until ``max_triangles`` triangles are found."""
        weight = per_head / n_cand
        found = drawn = 0
        while found < max_triangles and drawn < _CANDIDATE_LIMIT:
            m = min(100_000, _CANDIDATE_LIMIT - drawn)
            h = gen.choice(per_head.size, m, p=weight)
            a = gen.integers(0, deg[h])
            b = gen.integers(0, deg[h] - 1)
            b = b + (b >= a)
            lo = starts[h]
            j, k = tails[lo + np.minimum(a, b)], tails[lo + np.maximum(a, b)]
            tri = _triangles(np.column_stack([heads[lo], j, k]))[:max_triangles - found]
            drawn += m
            found += tri.shape[0]
            yield tri

    if exhaustive:
        listed = [_triangles(t) for t in _listed()]
        tris = np.concatenate(listed) if listed else np.zeros((0, 3), np.int64)
        sampled = tris.shape[0] > max_triangles
        if sampled:                       # a uniform subset of the triangles
            tris = tris[np.sort(gen.choice(tris.shape[0], max_triangles, replace=False))]
        chunks = (tris[s:s + 100_000] for s in range(0, tris.shape[0], 100_000))
    else:
        sampled = True
        chunks = _drawn()
    return chunks, sampled


def cycle_inconsistency_arrays(pairs, maps, sizes, *, max_triangles: int = 200_000,
                               rng=None) -> dict[str, float]:
    """:func:`cycle_inconsistency` on stacked arrays (no dict; for large collections).

    ``pairs`` is ``(Q, 2)`` with ``pairs[q, 0] < pairs[q, 1]``; ``maps[q]`` is the assignment
    ``pairs[q, 0] -> pairs[q, 1]`` padded with -1 to a common width; ``sizes`` holds the number
    of nodes of every object. Duplicate pairs: the first occurrence is used.

    Parameters
    ----------
    pairs : array_like of shape (Q, 2), int
        Object pairs ``i < j``.
    maps : array_like of shape (Q, n), int
        ``maps[q]`` the assignment of ``pairs[q]``, padded with ``-1``.
    sizes : array_like of shape (N,), int
        Number of nodes of every object.
    max_triangles : int, default=200000
        Most triangles checked (a uniform sample of them beyond; see
        :func:`cycle_inconsistency`).
    rng : None, int or numpy.random.Generator, optional
        Draws the triangles when sampling.

    Returns
    -------
    dict
        As :func:`cycle_inconsistency`.

    Raises
    ------
    ValueError, TypeError
        Mis-shaped or non-integer arrays, pairs out of range or not ``i < j``, map entries that
        are not node indices, maps that are not assignments of their pair (a target used
        twice, beyond the target object, or a source node beyond the source object).

    Examples
    --------
    >>> cycle_inconsistency_arrays([[0, 1], [1, 2], [0, 2]], [[1, 0], [1, 0], [0, 1]], [2, 2, 2])
    {'n_triangles': 1, 'inconsistent_triangles': 0.0, 'cycle_error': 0.0, 'sampled': False}
    """
    # integral floats and (as ever here) bools are accepted; NaN is a ValueError
    policy = {"integral_floats": True, "allow_bool": True, "finite": True}
    pairs = check_int_array(pairs, "pairs", ndim=2, **policy)
    maps = check_int_array(maps, "maps", ndim=2, **policy)
    sizes = check_int_array(sizes, "sizes", ndim=1, **policy)
    if pairs.shape[1:] != (2,) or maps.shape[0] != pairs.shape[0]:
        raise ValueError(f"`pairs` must be (Q, 2) and `maps` (Q, n), got shapes {pairs.shape} "
                         f"and {maps.shape}")
    if pairs.size and (pairs.min() < 0 or pairs.max() >= sizes.size
                       or np.any(pairs[:, 0] >= pairs[:, 1])):
        raise ValueError(f"`pairs` must hold object indices i < j in [0, {sizes.size})")
    if maps.size and (maps.min() < UNMATCHED or maps.max() >= max(int(sizes.max()), 1)):
        raise ValueError("`maps` entries must be node indices or -1")
    _check_map_rows(pairs, maps, sizes)
    check_int(max_triangles, "max_triangles", minimum=1, maximum=_MAX_TRIANGLES)
    gen = as_generator(rng)         # checked even when no sampling needs it
    n_obj = int(sizes.shape[0])
    n_max = max(maps.shape[1], int(sizes.max(initial=0)))
    if n_max > maps.shape[1] and maps.shape[0] * n_max > MAX_NODES:   # padding, not input
        raise ValueError(f"`sizes` gives an object of {n_max} nodes: the {maps.shape[0]} maps "
                         f"padded to that width would need more than {MAX_NODES:.0e} entries; "
                         "check `sizes`")
    if n_obj > 2**31:
        raise ValueError(f"`sizes` must describe at most 2**31 objects, got {n_obj}")
    if maps.shape[1] < n_max:
        maps = np.concatenate([maps, np.full((maps.shape[0], n_max - maps.shape[1]),
                                             UNMATCHED, maps.dtype)], 1)
    partial = bool(np.any(maps[np.arange(n_max)[None, :] < sizes[pairs[:, 0]][:, None]] < 0))
    if partial:                   # inverses, for the two other orientations of a triangle
        inv = np.full_like(maps, UNMATCHED)
        q, u = np.nonzero(maps >= 0)
        inv[q, maps[q, u]] = u
    # pair (i, j) -> its row, first occurrence winning (an (N, N) table was N**2 entries:
    # 10**4 objects and up failed)
    pid = pair_rows(pairs, n_obj)

    # a column of -1 so that "unmatched" indexes to unmatched: ajk_pad[-1] = -1
    maps_pad = np.concatenate([maps, np.full((maps.shape[0], 1), UNMATCHED, maps.dtype)], 1)
    chunks, sampled = _triangle_chunks(pairs, pid, max_triangles, gen)

    n_tri = 0
    bad = 0
    err = 0.0
    for tri in chunks:
        qij = pid(tri[:, 0], tri[:, 1])
        qjk = pid(tri[:, 1], tri[:, 2])
        qik = pid(tri[:, 0], tri[:, 2])
        ok = (qij >= 0) & (qjk >= 0) & (qik >= 0)
        if not ok.any():
            continue
        qij, qjk, qik, tri = qij[ok], qjk[ok], qik[ok], tri[ok]
        if not partial:
            aij = maps[qij]                                   # (t, n_max)
            via = np.take_along_axis(maps_pad[qjk], np.where(aij >= 0, aij, n_max), axis=1)
            frac = (via != maps[qik]).sum(1) / np.maximum(sizes[tri[:, 0]], 1)
        else:
            pad = np.full((inv.shape[0], 1), UNMATCHED, maps.dtype)
            inv_pad = np.concatenate([inv, pad], 1)
            frac = np.zeros(tri.shape[0])
            # (first hop, second hop (padded), direct map, source object)
            for first, second, direct, src in (
                    (maps[qij], maps_pad[qjk], maps[qik], tri[:, 0]),     # i -> j -> k
                    (maps[qik], inv_pad[qjk], maps[qij], tri[:, 0]),      # i -> k -> j
                    (inv[qij], maps_pad[qik], maps[qjk], tri[:, 1])):     # j -> i -> k
                hit = first >= 0
                via = np.take_along_axis(second, np.where(hit, first, n_max), axis=1)
                wrong = (hit & (via != direct)).sum(1) / np.maximum(sizes[src], 1)
                frac = np.maximum(frac, wrong)
        n_tri += int(tri.shape[0])
        bad += int(np.count_nonzero(frac))
        err += float(frac.sum())
    return {
        "n_triangles": n_tri,
        "inconsistent_triangles": float(bad / n_tri) if n_tri else 0.0,
        "cycle_error": float(err / n_tri) if n_tri else 0.0,
        "sampled": bool(sampled),
    }


# ----------------------------------------------------------------------------------------------
# multi-matchings: universe labels, the one place where labels become pairwise maps
# ----------------------------------------------------------------------------------------------

_DENSE_INVERSE = 2**24     # entries of MultiMatching's dense slot -> node table (128 MiB)


def _pad(labels: Sequence[np.ndarray]) -> np.ndarray:
    n_max = max((lab.shape[0] for lab in labels), default=0)
    out = np.full((len(labels), n_max), UNMATCHED, dtype=np.int64)
    for g, lab in enumerate(labels):
        out[g, : lab.shape[0]] = lab
    return out


@dataclass(frozen=True, eq=False)
class MultiMatching:
    """A cycle-consistent multi-matching: every node of every object placed in a universe.

    ``labels[g][u]`` is the universe slot (``0 .. n_universe - 1``) of node ``u`` of object ``g``,
    ``-1`` when the node is not placed; no two nodes of one object share a slot. The pairwise
    map ``i -> j`` sends ``u`` to the node of ``j`` in the same slot (``-1`` when there is none),
    so every derived map is cycle-consistent by construction. This is the one place where labels
    become pairwise maps: synchronization results carry one as ``.matching`` and the synthetic
    generators carry their ground truth as ``.ground_truth``.

    Parameters
    ----------
    labels : sequence of 1-d int arrays
        One array per object (objects may have different sizes, also 0).
    n_universe : int, optional
        Universe size ``d``; default ``max(labels) + 1``. Must exceed every label.

    Raises
    ------
    ValueError, TypeError
        Labels that are not 1-d integer arrays, below -1 or ``>= n_universe``, or that put two
        nodes of one object in the same slot.

    Examples
    --------
    >>> import numpy as np
    >>> from transync.permutations import MultiMatching
    >>> m = MultiMatching([np.array([0, 1, 2]), np.array([2, 0, -1]), np.array([1, 2])])
    >>> m.n_universe, m.sizes.tolist()
    (3, [3, 3, 2])
    >>> m.pairwise(0, 1)                   # node 0 of object 0 sits with node 1 of object 1
    array([ 1, -1,  0])
    >>> m.absolute(2).astype(int)
    array([[0, 1, 0],
           [0, 0, 1]])
    >>> truth = MultiMatching([np.array([0, 1, 2]), np.array([2, 0, 1]), np.array([1, 2])])
    >>> truth.accuracy(m)                  # fraction of the true correspondences m recovers
    0.714...
    """

    labels: tuple[np.ndarray, ...]
    n_universe: int | None = None
    _padded: np.ndarray = field(init=False, repr=False)
    _inv: np.ndarray | tuple | None = field(init=False, repr=False, default=None)
    _sizes: np.ndarray = field(init=False, repr=False)

    def __post_init__(self):
        labels = self.labels
        if isinstance(labels, np.ndarray) and labels.ndim == 2:
            labels = list(labels)
        if isinstance(labels, (str, bytes)) or not isinstance(labels, Sequence):
            raise TypeError("`labels` must be a sequence of 1-d int arrays (one per object), got "
                            f"{type(labels).__name__}")
        checked = tuple(_as_label_array(lab, f"labels[{g}]") for g, lab in enumerate(labels))
        padded = _pad(checked)
        top = int(padded.max(initial=-1))
        if padded.size and padded.min() < UNMATCHED:
            g = int(np.flatnonzero((padded < UNMATCHED).any(1))[0])
            raise ValueError(f"`labels[{g}]` entries must be >= -1, got {int(checked[g].min())}")
        if self.n_universe is None:
            d = top + 1
        else:
            d = check_int(self.n_universe, "n_universe", minimum=0)
            if top >= d:
                g = int(np.flatnonzero((padded >= d).any(1))[0])
                raise ValueError(f"`labels[{g}]` entries must be < n_universe={d}, got "
                                 f"{int(checked[g].max())}")
        srt = np.sort(padded, axis=1)
        dup = (srt[:, 1:] == srt[:, :-1]) & (srt[:, 1:] >= 0)
        if dup.any():
            g = int(np.flatnonzero(dup.any(1))[0])
            raise ValueError(f"`labels[{g}]` must be injective: two nodes of object {g} share "
                             "a universe slot")
        for lab in checked:
            lab.flags.writeable = False
        # slots renumbered 0 .. k-1 over the used ones (k <= number of nodes): the tables
        # behind pairwise maps never depend on n_universe
        used, inverse = np.unique(padded, return_inverse=True)
        compact = (inverse.reshape(padded.shape) - int(used.size and used[0] < 0)).astype(np.int64)
        compact[padded < 0] = UNMATCHED
        compact.flags.writeable = False
        object.__setattr__(self, "labels", checked)
        object.__setattr__(self, "n_universe", int(d))
        object.__setattr__(self, "_padded", compact)
        sizes = np.array([lab.shape[0] for lab in checked], dtype=np.int64)
        sizes.flags.writeable = False
        object.__setattr__(self, "_sizes", sizes)

    @classmethod
    def from_labels(cls, labels, n_universe: int | None = None) -> MultiMatching:
        """Build (and validate) from labels; a :class:`MultiMatching` is returned as is."""
        if isinstance(labels, MultiMatching) and n_universe in (None, labels.n_universe):
            return labels
        if isinstance(labels, MultiMatching):
            labels = labels.labels
        return cls(labels, n_universe)

    def __eq__(self, other) -> bool:
        if not isinstance(other, MultiMatching):
            return NotImplemented
        return (self.n_universe == other.n_universe and self.n_objects == other.n_objects
                and all(np.array_equal(a, b) for a, b in zip(self.labels, other.labels)))

    __hash__ = None  # type: ignore[assignment]

    @property
    def n_objects(self) -> int:
        return len(self.labels)

    @property
    def sizes(self) -> np.ndarray:
        """Number of nodes of every object, ``(n_objects,)`` int (read-only)."""
        return self._sizes

    def _object(self, g, name: str) -> int:
        g = check_int(g, name)
        if not 0 <= g < self.n_objects:
            raise ValueError(f"`{name}` must be an object index in [0, {self.n_objects}), got {g}")
        return g

    def _inverse(self):
        """``inv[g, a]`` = node of object ``g`` in (compact) slot ``a``; the last column (= slot
        -1) is -1. Above ``_DENSE_INVERSE`` entries (10**5 objects of 2 nodes in distinct slots
        asked for 149 GiB) it is ``(keys, nodes, k)`` instead: the sorted codes ``g * k + a`` of
        the placed nodes, looked up by binary search (:meth:`_lookup`)."""
        if self._inv is None:
            k = int(self._padded.max(initial=-1)) + 1
            g, u = np.nonzero(self._padded >= 0)
            if self.n_objects * (k + 1) <= _DENSE_INVERSE:
                inv = np.full((self.n_objects, k + 1), UNMATCHED, dtype=np.int64)
                inv[g, self._padded[g, u]] = u
                inv.flags.writeable = False
            else:
                keys = g.astype(np.int64) * k + self._padded[g, u]
                order = np.argsort(keys, kind="stable")
                inv = (keys[order], u[order].astype(np.int64), k)
            object.__setattr__(self, "_inv", inv)             # computed once (frozen object)
        return self._inv

    def _lookup(self, objs: np.ndarray, slots: np.ndarray) -> np.ndarray:
        """Node of object ``objs`` in compact slot ``slots`` (broadcast), -1 for none / slot -1."""
        inv = self._inverse()
        if isinstance(inv, np.ndarray):
            return inv[objs, slots]                                   # slot -1 -> column -1
        keys, nodes, k = inv
        code = np.asarray(objs, np.int64) * k + slots
        at = np.minimum(np.searchsorted(keys, code), max(keys.size - 1, 0))
        hit = (slots >= 0) & (keys[at] == code) if keys.size else np.zeros(code.shape, bool)
        return np.where(hit, nodes[at] if keys.size else UNMATCHED, UNMATCHED)

    def pairwise(self, i: int, j: int) -> np.ndarray:
        """Assignment from object ``i`` to object ``j`` (``-1`` = no partner in ``j``).

        The rows of ``X_i X_j^T``: ``pairwise(g, g)`` sends each placed node to itself and an
        unplaced one to -1 (the diagonal blocks of :meth:`to_matrix` are identities by
        convention, unplaced nodes included)."""
        i, j = self._object(i, "i"), self._object(j, "j")
        return self._lookup(np.int64(j), self._padded[i, : self._sizes[i]])

    def check_pairs(self, pairs=None) -> np.ndarray:
        """``pairs`` validated as a ``(P, 2)`` int array of object indices; ``None``: every
        ``i < j``."""
        if pairs is None:
            return np.column_stack(np.triu_indices(self.n_objects, 1)).astype(np.int64)
        return check_index_pairs(pairs, self.n_objects)

    def pairwise_array(self, pairs=None) -> np.ndarray:
        """Maps of many pairs at once: ``(P, n_max)`` int, row ``p`` the map ``i -> j`` of
        ``pairs[p] = (i, j)`` padded with -1 (default: every ``i < j``)."""
        pairs = self.check_pairs(pairs)
        return self._lookup(pairs[:, 1][:, None], self._padded[pairs[:, 0]])

    def pairwise_dict(self, pairs=None) -> dict[tuple[int, int], np.ndarray]:
        """``{(i, j): pairwise(i, j)}`` for ``pairs`` (default: every ``i < j``)."""
        pairs = self.check_pairs(pairs)
        maps = self.pairwise_array(pairs)
        sizes = self.sizes
        return {(int(i), int(j)): maps[p, : sizes[i]].copy()
                for p, (i, j) in enumerate(pairs.tolist())}

    def absolute(self, g: int) -> np.ndarray:
        """The ``(n_g, n_universe)`` 0/1 matrix ``X_g`` (node -> universe slot)."""
        lab = self.labels[self._object(g, "g")]
        if lab.shape[0] * self.n_universe > MAX_NODES:   # (the converter named its own `n2`)
            raise ValueError(f"absolute({g}) would build a {lab.shape[0]} x {self.n_universe} "
                             f"matrix (more than {MAX_NODES:.0e} entries): the universe is too "
                             "large for dense maps; use labels[g]")
        return assignment_to_matrix(lab, self.n_universe)

    def to_matrix(self, *, max_size: int = 20000) -> np.ndarray:
        """The ``(sum n_g, sum n_g)`` 0/1 block matrix with blocks ``P_ij = X_i X_j^T``.

        Diagonal blocks are identities (also for unplaced nodes). Meant for small problems: a
        total above ``max_size`` nodes raises ``ValueError``.
        """
        max_size = check_int(max_size, "max_size", minimum=0)     # NaN switched it off
        total = int(self.sizes.sum())
        if total > max_size:
            raise ValueError(f"to_matrix() would build a {total} x {total} matrix (more than "
                             f"max_size={max_size} nodes); use pairwise(i, j) for large problems")
        if total > _MAX_MATRIX_SIDE:
            raise ValueError(f"to_matrix() would build a {total} x {total} matrix (at most "
                             f"{_MAX_MATRIX_SIDE} x {_MAX_MATRIX_SIDE} whatever max_size, 3.2 GB); "
                             "use pairwise(i, j) for large problems")
        k = int(self._padded.max(initial=-1)) + 1           # used slots only: same X X^T
        real = np.arange(self._padded.shape[1])[None, :] < self._sizes[:, None]
        lab = self._padded[real]                  # the real nodes, object by object
        X = np.zeros((total, k))
        placed = np.flatnonzero(lab >= 0)
        X[placed, lab[placed]] = 1.0
        T = X @ X.T
        np.fill_diagonal(T, 1.0)
        return T

    def accuracy(self, other, *, pairs=None) -> float:
        """Fraction of the correspondences of ``self`` (the reference) that ``other`` recovers.

        A correspondence is a node ``u`` of ``i`` and a node ``v`` of ``j`` (``i != j``) in the
        same slot of ``self``; it is recovered when ``other`` also matches ``u`` to ``v``.
        ``other`` is a :class:`MultiMatching` (or its labels, or anything with a ``.matching``),
        or a mapping ``{(i, j): assignment}`` of pairwise maps, e.g. outputs that are not
        cycle-consistent (a missing pair recovers nothing; ``(j, i)`` is used, inverted, when
        only it is given). Evaluated over every ``i < j`` or over the ``(P, 2)`` ``pairs``;
        1.0 when there is no correspondence to recover.
        """
        pairs = self.check_pairs(pairs)
        if pairs.shape[0] == 0:
            return 1.0
        if isinstance(other, Mapping):
            pred = self.maps_from(other, pairs)
        else:
            if not isinstance(other, MultiMatching) and isinstance(
                    getattr(other, "matching", None), MultiMatching):
                other = other.matching
            if other is None or isinstance(other, (str, bytes, int, float)):
                raise TypeError("`other` must be a MultiMatching, its labels, a result with a "
                                ".matching or a dict {(i, j): assignment}, got "
                                f"{type(other).__name__}")
            other = MultiMatching.from_labels(other)
            if other.n_objects != self.n_objects or not np.array_equal(other.sizes, self.sizes):
                raise ValueError(f"`other` must hold {self.n_objects} objects of sizes "
                                 f"{self.sizes.tolist()[:10]}, got {other.n_objects} objects of "
                                 f"sizes {other.sizes.tolist()[:10]}")
            pred = None
        hit = tot = 0
        for start in range(0, pairs.shape[0], 20000):
            chunk = pairs[start:start + 20000]
            true_v = self.pairwise_array(chunk)
            pred_v = (other.pairwise_array(chunk) if pred is None
                      else pred[start:start + 20000])
            ok = true_v >= 0
            tot += int(ok.sum())
            hit += int((ok & (pred_v == true_v)).sum())
        return float(hit / tot) if tot else 1.0

    def maps_from(self, maps: Mapping, pairs: np.ndarray, *, name: str = "other") -> np.ndarray:
        """Pairwise assignments ``{(i, j): assignment}`` (need not be consistent) as a
        ``(P, n_max)`` array aligned with ``pairs`` (validated against this matching's sizes;
        ``(j, i)`` used, inverted, when only it is given; a missing pair gives ``-1`` rows).
        Every key must be a pair of distinct object indices, used or not (``name``: the
        argument, for messages)."""
        pairs = self.check_pairs(pairs)
        sizes = self.sizes
        N = self.n_objects
        for key in maps:
            if not (isinstance(key, tuple) and len(key) == 2
                    and all(isinstance(k, (int, np.integer)) and not isinstance(k, bool)
                            and 0 <= k < N for k in key) and key[0] != key[1]):
                raise ValueError(f"`{name}` keys must be pairs (i, j) of distinct object indices "
                                 f"in [0, {N}), got key {key!r}")
        n_max = int(sizes.max(initial=0))
        out = np.full((pairs.shape[0], n_max), UNMATCHED, dtype=np.int64)
        for p, (i, j) in enumerate(pairs.tolist()):
            if (i, j) in maps:
                a = check_assignment(maps[(i, j)], f"{name}[{(i, j)}]", n1=int(sizes[i]),
                                     n2=int(sizes[j]))
            elif (j, i) in maps:
                a = invert(check_assignment(maps[(j, i)], f"{name}[{(j, i)}]", n1=int(sizes[j]),
                                            n2=int(sizes[i])), int(sizes[i]))
            else:
                continue
            out[p, : a.shape[0]] = a
        return out
