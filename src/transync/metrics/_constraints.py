"""Constraint violations of (possibly soft) multi-matchings: CVR, CVVR, ACVV.

Summary: methods page *Synthetic protocols and evaluation measures* of the documentation.

Two families of constraints ``g(x) <= 1`` are measured, separately:

* **(c1) capacity.** Pairwise input: every row sum and every column sum of every block ``X_ij``
  (``n_i + n_j`` constraints per pair). Absolute input (maps ``X_i`` into a universe of ``d``
  slots): every column sum of every ``X_i`` (``d`` constraints per object: a slot takes at most
  one node of an object).
* **(c2) transitivity.** ``X_ij[u, v] + X_jk[v, w] - X_ik[u, w] <= 1`` for every triple of distinct
  objects ``(i, j, k)`` with ``i < k`` (``j`` is the middle object; ``(k, j, i)`` gives the same
  constraints) whose three pairs are all available, and every node triple ``(u, v, w)`` of
  ``n_i x n_j x n_k``. For absolute input the blocks are ``X_ij = X_i X_j^T``.

With the violation of a constraint ``max(0, g(x) - 1)`` (counted when it exceeds ``tol``):

* **CVR** = violated constraints / constraints;
* **CVVR** = sum of violations / sum of ``|g(x)|`` (total violation relative to total mass);
* **ACVV** = sum of violations / violated constraints (0 when none is violated).

Exact and sampled evaluation
----------------------------
Discrete blocks that are partial permutations (assignments, a
:class:`~transync.permutations.MultiMatching`, 0/1 matrices with at most one 1 per row and per
column) are evaluated *exactly*, every node triple of every object triple, in ``O(n)`` per
object triple: a violated transitivity constraint is a node ``u`` with ``X_ij X_jk`` sending it to
a node ``w`` that ``X_ik`` does not, and the sums of ``|g|`` follow from counts of matched nodes.
Absolute maps that are partial permutations (a MultiMatching) violate no transitivity constraint
by construction; their counts follow in closed form from how many objects hold each universe
slot, in ``O(sum n_i)`` whatever the number of objects.
Any other input (soft matrices, 0/1 matrices with a row or a column of several ones) is evaluated
on every node triple when there are at most ``max_triples`` transitivity constraints; above that,
``max_triples`` node triples ``((i, u), (j, v), (k, w))`` are drawn uniformly at random with
replacement among all transitivity constraints (an object triple with probability proportional
to ``n_i n_j n_k``, then the three nodes uniformly), and the three ratios are estimated on them
(``sampled=True``; counts then refer to the sample). On a complete view graph (absolute maps)
the object triples are drawn without listing them; otherwise they are listed a chunk at a
time. Capacity is always exhaustive.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .._validation import as_generator, check_array, check_int, check_positive
from ..permutations import MAX_NODES, MultiMatching, check_assignment, pair_rows

__all__ = ["ConstraintStats", "ConstraintViolations", "constraint_violations"]

_CHUNK = 4_000_000          # entries of a (t, n, n, n) work array in the exhaustive soft path
_TRIPLE_CHUNK = 1_000_000   # object triples listed at a time


@dataclass(frozen=True)
class ConstraintStats:
    """Violation statistics of one family of constraints ``g(x) <= 1``.

    Attributes
    ----------
    n_constraints : int
        Constraints in the family.
    n_evaluated : int
        Constraints evaluated: ``n_constraints``, or the sample size when ``sampled``.
    n_violated : int
        Evaluated constraints with ``g(x) - 1 > tol``.
    violation : float
        Sum of ``g(x) - 1`` over the violated evaluated constraints.
    magnitude : float
        Sum of ``|g(x)|`` over the evaluated constraints.
    sampled : bool
        The evaluated constraints are a uniform random sample.

    Examples
    --------
    >>> s = ConstraintStats(n_constraints=10, n_evaluated=10, n_violated=2, violation=0.5,
    ...                     magnitude=8.0)
    >>> s.cvr, s.cvvr, s.acvv
    (0.2, 0.0625, 0.25)
    """

    n_constraints: int
    n_evaluated: int
    n_violated: int
    violation: float
    magnitude: float
    sampled: bool = False

    @property
    def cvr(self) -> float:
        """Constraint violation ratio: violated / evaluated constraints (0 when none)."""
        return self.n_violated / self.n_evaluated if self.n_evaluated else 0.0

    @property
    def cvvr(self) -> float:
        """Constraint violation value ratio: sum of violations / sum of ``|g(x)|``."""
        return self.violation / self.magnitude if self.magnitude else 0.0

    @property
    def acvv(self) -> float:
        """Average constraint violation value: sum of violations / violated constraints."""
        return self.violation / self.n_violated if self.n_violated else 0.0


@dataclass(frozen=True)
class ConstraintViolations:
    """Result of :func:`constraint_violations`: capacity (c1) and transitivity (c2) separately.

    ``info`` holds ``input`` (``"pairwise"`` or ``"absolute"``), ``transitivity_mode``
    (``"exact"``, ``"exhaustive"`` or ``"sampled"``), ``n_pairs`` and ``n_object_triples``.

    Attributes
    ----------
    capacity : ConstraintStats
        Row, column and slot capacities (c1).
    transitivity : ConstraintStats
        Transitivity over triples of objects (c2).
    info : dict
        How the statistics were computed (exact or sampled, sizes).

    Examples
    --------
    >>> import numpy as np
    >>> from transync.metrics import constraint_violations
    >>> maps = {(0, 1): np.array([0, 1]), (1, 2): np.array([0, 1]), (0, 2): np.array([1, 0])}
    >>> v = constraint_violations(maps)                         # one inconsistent triangle
    >>> v.capacity.n_violated, v.transitivity.n_violated > 0
    (0, True)
    """

    capacity: ConstraintStats
    transitivity: ConstraintStats
    info: Mapping[str, Any] = field(default_factory=dict)

    def as_dict(self) -> dict[str, float]:
        """Flat ``{"capacity_cvr": ..., "transitivity_acvv": ..., ...}`` (for tables)."""
        out: dict[str, float] = {}
        for name in ("capacity", "transitivity"):
            s = getattr(self, name)
            out.update({f"{name}_cvr": s.cvr, f"{name}_cvvr": s.cvvr, f"{name}_acvv": s.acvv,
                        f"{name}_violated": s.n_violated, f"{name}_evaluated": s.n_evaluated,
                        f"{name}_constraints": s.n_constraints})
        return out


# ----------------------------------------------------------------------------------------------
# input parsing
# ----------------------------------------------------------------------------------------------

@dataclass
class _Pairs:
    """Blocks of the pairs ``i < j``: partial permutations (``fwd``/``bwd`` maps) or dense."""

    sizes: np.ndarray              # (N,) int64
    pairs: np.ndarray              # (Q, 2) int64, i < j
    fwd: np.ndarray | None         # (Q, n_max) map i -> j, -1 unmatched / padding
    bwd: np.ndarray | None         # (Q, n_max) map j -> i
    dense: np.ndarray | None       # (Q, n_max, n_max) float block i -> j, zero padded


@dataclass
class _Labels:
    """Absolute maps that are partial permutations: each object's node -> slot (-1: none)."""

    sizes: np.ndarray              # (N,) int64
    labels: list                   # N arrays (n_i,), every slot at most once per object
    n_universe: int


MAX_OBJECTS = 10**7      # largest object index + 1 (one size per object is kept)


def _check_work(n_entries: int, what: str) -> None:
    if n_entries > MAX_NODES:
        raise ValueError(f"`X` would need {what} of {n_entries:.3g} entries (more than "
                         f"{MAX_NODES:.0e}); evaluate fewer or smaller objects")


#: largest absolute value of a soft correspondence entry: sums and products of two entries
#: over up to MAX_NODES terms stay finite (1e308 entries made NaN rates and inf magnitudes)
SOFT_LIMIT = 1e100


def _soft_block(v, name: str) -> np.ndarray:
    M = check_array(v, name, ndim=2)
    top = float(np.abs(M).max(initial=0.0))
    if top > SOFT_LIMIT:
        raise ValueError(f"`{name}` has values up to {top:.3g}: soft correspondences must stay "
                         f"within +-{SOFT_LIMIT:g} (they are about 0 .. 1)")
    return M


def _is_partial_permutation(M: np.ndarray) -> bool:
    return bool(np.all((M == 0) | (M == 1)) and np.all(M.sum(1) <= 1) and np.all(M.sum(0) <= 1))


def _is_regular(v) -> bool:
    try:
        np.shape(v)
    except ValueError:                       # ragged nesting: check_array reports it
        return False
    return True


def _check_sizes(sizes, n_needed: int | None) -> np.ndarray | None:
    if sizes is None:
        return None
    arr = check_array(sizes, "sizes", ndim=1)
    if arr.size and (np.any(arr != np.round(arr)) or arr.min() < 0 or arr.max() > MAX_NODES):
        raise ValueError(f"`sizes` must hold integers in [0, {MAX_NODES:.0e}], got "
                         f"{arr.tolist()[:10]}")
    arr = arr.astype(np.int64)
    if n_needed is not None and arr.size < n_needed:
        raise ValueError(f"`sizes` must give the size of every object (at least {n_needed}), "
                         f"got {arr.size}")
    return arr


def _parse_pairwise(X: Mapping, sizes) -> _Pairs:
    keys = []
    for key in X:
        if (not isinstance(key, tuple) or len(key) != 2
                or not all(isinstance(k, (int, np.integer)) and not isinstance(k, bool)
                           for k in key)
                or key[0] < 0 or key[1] < 0 or key[0] == key[1]):
            raise ValueError(f"`X` keys must be pairs (i, j) of distinct non-negative object "
                             f"indices, got {key!r}")
        keys.append((int(key[0]), int(key[1])))
    n_obj = max((max(k) for k in keys), default=-1) + 1
    if n_obj > MAX_OBJECTS:
        raise ValueError(f"`X` keys name object {n_obj - 1}: object indices must stay below "
                         f"{MAX_OBJECTS:.0e} (number the objects 0 .. N - 1)")
    given = _check_sizes(sizes, n_obj)
    known: dict[int, int] = {}
    lower: dict[int, int] = {}

    def fix(g: int, n: int, key) -> None:
        have = given[g] if given is not None else known.get(g)
        if have is not None and have != n:
            raise ValueError(f"`X[{key}]` implies {n} nodes for object {g}, but "
                             f"{'`sizes`' if given is not None else 'another block'} gives {have}")
        known[g] = n

    values = {}
    for (i, j), key in zip(keys, X):
        v = X[key]
        if _is_regular(v) and np.ndim(v) == 1:
            a = check_assignment(v, f"X[{(i, j)}]",
                                 n2=None if given is None else int(given[j]))
            fix(i, a.shape[0], (i, j))
            if a.size:
                lower[j] = max(lower.get(j, 0), int(a.max()) + 1)
            values[(i, j)] = a
        else:
            M = _soft_block(v, f"X[{(i, j)}]")
            fix(i, M.shape[0], (i, j))
            fix(j, M.shape[1], (i, j))
            values[(i, j)] = M
    if given is not None:
        size_arr = given
    else:
        size_arr = np.zeros(n_obj, dtype=np.int64)
        for g, n in lower.items():
            size_arr[g] = n
        for g, n in known.items():
            if n < lower.get(g, 0):
                raise ValueError(f"`X`: an assignment into object {g} uses node "
                                 f"{lower[g] - 1}, but object {g} has {n} nodes")
            size_arr[g] = n
    canon: dict[tuple[int, int], tuple[np.ndarray, bool]] = {}
    for (i, j), v in values.items():
        if i < j:
            canon[(i, j)] = (v, False)
    for (i, j), v in values.items():
        if i > j and (j, i) not in canon:
            canon[(j, i)] = (v, True)           # block j -> i; transposed below
    order = sorted(canon)
    pairs = np.array(order, dtype=np.int64).reshape(-1, 2)
    n_max = int(size_arr.max(initial=0))
    discrete = all(v.ndim == 1 or _is_partial_permutation(v) for v, _ in canon.values())
    Q = len(order)
    if discrete:
        _check_work(Q * n_max, "pairwise maps")
        fwd = np.full((Q, n_max), -1, dtype=np.int64)
        bwd = np.full((Q, n_max), -1, dtype=np.int64)
        for q, key in enumerate(order):
            v, flipped = canon[key]
            if v.ndim == 1:
                a = v
            else:
                a = np.full(v.shape[0], -1, dtype=np.int64)
                r, c = np.nonzero(v)
                a[r] = c
            u = np.flatnonzero(a >= 0)
            one, other = (bwd, fwd) if flipped else (fwd, bwd)
            one[q, u] = a[u]
            other[q, a[u]] = u
        return _Pairs(size_arr, pairs, fwd, bwd, None)
    _check_work(Q * n_max * n_max, "dense pairwise blocks")
    dense = np.zeros((Q, n_max, n_max))
    for q, key in enumerate(order):
        v, flipped = canon[key]
        i, j = key
        if v.ndim == 1:
            src, dst = (j, i) if flipped else (i, j)
            M = np.zeros((size_arr[src], size_arr[dst]))
            u = np.flatnonzero(v >= 0)
            M[u, v[u]] = 1.0
            v = M
        if flipped:
            v = v.T
        dense[q, : size_arr[i], : size_arr[j]] = v
    return _Pairs(size_arr, pairs, None, None, dense)


def _parse_absolute(X, tol: float) -> tuple[_Pairs, ConstraintStats]:
    """Absolute maps -> pairwise blocks ``X_i X_j^T`` and the capacity statistics."""
    if isinstance(X, MultiMatching):
        m = X
        sizes = m.sizes.astype(np.int64)
        d = m.n_universe
        placed = int(sum(int((lab >= 0).sum()) for lab in m.labels))
        cap = ConstraintStats(len(sizes) * d, len(sizes) * d, 0, 0.0, float(placed))
        return _Labels(sizes, [np.asarray(lab) for lab in m.labels], d), cap
    mats = []
    for g, M in enumerate(X):
        M = _soft_block(M, f"X[{g}]")
        if mats and M.shape[1] != mats[0].shape[1]:
            raise ValueError(f"`X[{g}]` must have {mats[0].shape[1]} columns (universe slots) "
                             f"like `X[0]`, got shape {M.shape}")
        mats.append(M)
    N = len(mats)
    if N == 0:
        raise ValueError("`X` must hold at least one absolute map, got an empty sequence")
    d = mats[0].shape[1]
    sizes = np.array([M.shape[0] for M in mats], dtype=np.int64)
    cols = np.stack([M.sum(0) for M in mats])                        # (N, d)
    cap = _stats_from_values(cols, tol)
    if all(_is_partial_permutation(M) for M in mats):   # labels: no pairwise block needed
        labels = [np.where(M.any(1), M.argmax(1), -1) if M.shape[1] else
                  np.full(M.shape[0], -1, np.int64) for M in mats]      # d = 0: no slot
        return _Labels(sizes, labels, d), cap
    n_max = int(sizes.max())
    _check_work(N * (N - 1) // 2 * n_max * n_max, "pairwise blocks X_i X_j^T")
    stack = np.zeros((N, n_max, d))
    for g, M in enumerate(mats):
        stack[g, : M.shape[0]] = M
    pairs = np.column_stack(np.triu_indices(N, 1)).astype(np.int64)
    blocks = np.einsum("qud,qvd->quv", stack[pairs[:, 0]], stack[pairs[:, 1]], optimize=True)
    pp = all(_is_partial_permutation(blocks[q, : sizes[i], : sizes[j]])
             for q, (i, j) in enumerate(pairs.tolist()))
    if pp:
        fwd = np.full((pairs.shape[0], n_max), -1, dtype=np.int64)
        bwd = np.full((pairs.shape[0], n_max), -1, dtype=np.int64)
        q, u, v = np.nonzero(blocks)
        fwd[q, u] = v
        bwd[q, v] = u
        return _Pairs(sizes, pairs, fwd, bwd, None), cap
    return _Pairs(sizes, pairs, None, None, blocks), cap


def _stats_from_values(g: np.ndarray, tol: float, n_constraints: int | None = None,
                       sampled: bool = False) -> ConstraintStats:
    """Statistics of constraints ``g <= 1`` from their values ``g`` (any shape)."""
    excess = g - 1.0
    bad = excess > tol
    return ConstraintStats(int(g.size if n_constraints is None else n_constraints), int(g.size),
                           int(np.count_nonzero(bad)), float(excess[bad].sum()),
                           float(np.abs(g).sum()), sampled)


# ----------------------------------------------------------------------------------------------
# capacity and transitivity
# ----------------------------------------------------------------------------------------------

def _pairwise_capacity(p: _Pairs, tol: float) -> ConstraintStats:
    n_i = p.sizes[p.pairs[:, 0]]
    n_j = p.sizes[p.pairs[:, 1]]
    total = int((n_i + n_j).sum())
    if p.dense is None:                       # partial permutations: every sum is 0 or 1
        mass = 2.0 * float((p.fwd >= 0).sum())
        return ConstraintStats(total, total, 0, 0.0, mass)
    rows = p.dense.sum(2)                     # padding rows/columns sum to 0: never violated
    cols = p.dense.sum(1)
    s1, s2 = _stats_from_values(rows, tol), _stats_from_values(cols, tol)
    return ConstraintStats(total, total, s1.n_violated + s2.n_violated,
                           s1.violation + s2.violation, s1.magnitude + s2.magnitude)


def _triple_chunks(p: _Pairs):
    """``(t, 3)`` triples ``(i, j, k)``, ``i < k``, ``j`` not in ``{i, k}``, all pairs present,
    in chunks of about :data:`_TRIPLE_CHUNK` (all of them in one array took 6 GB at N = 800).

    Built over the objects that appear in a pair only (renumbered in order, then mapped back):
    a single key ``(0, 3000)`` made a 3001-object O(N^3) loop.
    """
    ids, local = np.unique(p.pairs, return_inverse=True)
    local = local.reshape(-1, 2)
    m = ids.shape[0]
    _check_work(m * m, "an object adjacency")
    have = np.zeros((m, m), dtype=bool)
    have[local[:, 0], local[:, 1]] = True
    have |= have.T
    out, count = [], 0
    for i in range(m):
        # j, k with have[i, j], have[j, k], have[i, k], k > i
        nb = np.flatnonzero(have[i])
        nb_k = nb[nb > i]
        if not nb_k.size:
            continue
        jk = have[np.ix_(nb, nb_k)]
        j, k = np.nonzero(jk)
        if j.size:
            out.append(np.column_stack([np.full(j.size, i), nb[j], nb_k[k]]))
            count += j.size
        if count >= _TRIPLE_CHUNK:
            yield ids[np.concatenate(out)]
            out, count = [], 0
    if out:
        yield ids[np.concatenate(out)]


def _complete_triples(p: _Pairs) -> tuple[np.ndarray, int] | None:
    """The objects of ``p`` and their number of object triples when every pair of them is
    present (absolute maps; a complete dict), else None."""
    ids = np.unique(p.pairs)
    m = ids.shape[0]
    if p.pairs.shape[0] != m * (m - 1) // 2:
        return None
    return ids, 3 * (m * (m - 1) * (m - 2) // 6)


def _triple_weights(p: _Pairs, tri: np.ndarray) -> np.ndarray:
    """``n_i n_j n_k`` of every triple: its number of node triples (transitivity constraints)."""
    sz = p.sizes.astype(np.int64)
    return sz[tri[:, 0]] * sz[tri[:, 1]] * sz[tri[:, 2]]


def _elementary3(sizes: np.ndarray) -> int:
    """``sum_{a < b < c} n_a n_b n_c`` exactly (Newton's identities on Python integers)."""
    values, counts = np.unique(sizes, return_counts=True)
    p1 = p2 = p3 = 0
    for v, c in zip(values.tolist(), counts.tolist()):
        p1, p2, p3 = p1 + c * v, p2 + c * v**2, p3 + c * v**3
    return (p1**3 - 3 * p1 * p2 + 2 * p3) // 6


def _transitivity_labels(lab: _Labels) -> tuple[ConstraintStats, int, int]:
    """Transitivity of absolute partial permutations, in closed form, O(sum n_i): no constraint
    is violated (``X_ij X_jk`` sends a node to the node of the same slot, as ``X_ik`` does),
    and the counts and ``sum |g|`` follow from how many objects hold each slot (``c_l``).

    Over the triples ``(i, j, k)``, ``i < k``, ``j`` not in ``{i, k}`` (each unordered triple
    three times), ``sum |g| = sum nnz(A) n_k + nnz(B) n_i + nnz(C) n_j - 2 |L_i & L_j & L_k|``
    with ``nnz(X_xy) = |L_x & L_y|``; summed, ``3 sum_{x < y} |L_x & L_y| (P - n_x - n_y)
    - 6 sum_l C(c_l, 3)``, ``P = sum n``. Returns the statistics, the number of object pairs
    and of object triples.
    """
    sizes = lab.sizes.astype(np.int64)
    N = sizes.shape[0]
    held = [np.asarray(x)[np.asarray(x) >= 0] for x in lab.labels]
    owner = np.repeat(np.arange(N), [h.size for h in held])
    slots = np.concatenate(held) if held else np.zeros(0, np.int64)
    c = np.bincount(slots.astype(np.int64), minlength=lab.n_universe).astype(np.int64)
    # r_x = sum over x's placed nodes of (objects sharing its slot - 1) = sum_y!=x |L_x & L_y|
    r = np.bincount(owner, weights=(c[slots] - 1).astype(np.float64), minlength=N)
    r = np.rint(r).astype(np.int64)
    P = int(sizes.sum())
    shared = sum(int(v) * (int(v) - 1) for v in c[c > 1].tolist())   # sum_x!=y |L_x & L_y|
    pair_sum = (P * shared - 2 * sum(int(a) * int(b) for a, b in zip(sizes, r) if b)) // 2
    triple_sum = sum(int(v) * (int(v) - 1) * (int(v) - 2) // 6 for v in c[c > 2].tolist())
    n_tot = 3 * _elementary3(sizes)
    mag = 3 * pair_sum - 6 * triple_sum
    return (ConstraintStats(n_tot, n_tot, 0, 0.0, float(mag)), N * (N - 1) // 2,
            3 * (N * (N - 1) * (N - 2) // 6))


def _pair_index(p: _Pairs):
    """``pid(a, b)``: the row of pair ``{a, b}`` in ``p.pairs``."""
    return pair_rows(p.pairs, p.sizes.shape[0])


def _transitivity_exact(p: _Pairs, tri: np.ndarray) -> ConstraintStats:
    """Partial-permutation blocks: every node triple of every object triple, O(n) per triple."""
    pid = _pair_index(p)
    n_max = p.fwd.shape[1]
    # row 2q: map i -> j of pair q (i < j), row 2q + 1: map j -> i; a last column of -1 so
    # that "unmatched" indexes to unmatched
    maps = np.full((2 * p.fwd.shape[0], n_max + 1), -1, dtype=np.int64)
    maps[0::2, :n_max] = p.fwd
    maps[1::2, :n_max] = p.bwd

    def oriented(a, b):                       # (t, n_max + 1) maps a -> b
        return maps[2 * pid(a, b) + (a > b)]

    sizes = p.sizes.astype(np.float64)
    n_tot = viol = 0
    mag = 0.0
    step = max(1, 2_000_000 // max(n_max, 1))
    for s in range(0, tri.shape[0], step):
        i, j, k = tri[s:s + step].T
        a, b, c = oriented(i, j), oriented(j, k), oriented(i, k)
        b_inv, c_inv = oriented(k, j), oriented(k, i)
        via = np.take_along_axis(b, np.where(a >= 0, a, n_max), axis=1)   # b[a[u]] or -1
        path = via >= 0
        viol += int(np.count_nonzero(path & (c != via)))
        abc = np.count_nonzero(path & (c == via), axis=1)
        ac = np.count_nonzero((a >= 0) & (c >= 0), axis=1)
        bc = np.count_nonzero((b_inv >= 0) & (c_inv >= 0), axis=1)
        nnz_a = np.count_nonzero(a >= 0, axis=1)
        nnz_b = np.count_nonzero(b >= 0, axis=1)
        nnz_c = np.count_nonzero(c >= 0, axis=1)
        # sum over (u, v, w) of |A + B - C| for 0/1 A, B, C: sum(A + B + C) - 2 #{C and (A or B)}
        mag += float((nnz_a * sizes[k] + nnz_b * sizes[i] + nnz_c * sizes[j]
                      - 2 * (ac + bc - abc)).sum())
        n_tot += int((sizes[i] * sizes[j] * sizes[k]).sum())
    return ConstraintStats(n_tot, n_tot, viol, float(viol), mag)


def _oriented_dense(p: _Pairs, pid, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    blocks = p.dense[pid(a, b)]
    return np.where((a < b)[:, None, None], blocks, blocks.transpose(0, 2, 1))


def _transitivity_dense(p: _Pairs, tri: np.ndarray, tol: float) -> ConstraintStats:
    """Every node triple of every object triple, on dense blocks (chunks of object triples)."""
    pid = _pair_index(p)
    n_max = p.dense.shape[1]
    ar = np.arange(n_max)
    step = max(1, _CHUNK // max(n_max ** 3, 1))
    n_tot = n_bad = 0
    viol = mag = 0.0
    for s in range(0, tri.shape[0], step):
        i, j, k = tri[s:s + step].T
        A = _oriented_dense(p, pid, i, j)
        B = _oriented_dense(p, pid, j, k)
        C = _oriented_dense(p, pid, i, k)
        G = A[:, :, :, None] + B[:, None, :, :] - C[:, :, None, :]
        real = ((ar < p.sizes[i][:, None])[:, :, None, None]
                & (ar < p.sizes[j][:, None])[:, None, :, None]
                & (ar < p.sizes[k][:, None])[:, None, None, :])
        excess = G - 1.0
        bad = real & (excess > tol)
        n_bad += int(np.count_nonzero(bad))
        viol += float(excess[bad].sum())
        mag += float(np.abs(G[real]).sum())
        n_tot += int(np.count_nonzero(real))
    return ConstraintStats(n_tot, n_tot, n_bad, viol, mag)


def _entries(flat: np.ndarray, pid, n: int, a, c, x, y) -> np.ndarray:
    """``X_ac[x, y]`` elementwise from the raveled ``(Q, n, n)`` blocks (stored for ``a < c``)."""
    fw = a < c
    return flat.take((pid(a, c) * n + np.where(fw, x, y)) * n + np.where(fw, y, x))


def _draw_complete(sizes: np.ndarray, ids: np.ndarray, m: int, rng) -> np.ndarray | None:
    """``m`` object triples ``(i, j, k)`` (``i < k``) of a complete set of objects ``ids``, each
    with probability ``n_i n_j n_k / total``, without listing them: three objects drawn
    independently with probability ``n / sum n``, redrawn unless distinct (each triple is two
    ordered draws). None when fewer than 1 draw in 1000 would be distinct (one object holding
    nearly every node): the triples are then listed."""
    n = sizes[ids].astype(np.float64)
    P = n.sum()
    if P == 0 or 6.0 * _elementary3(sizes[ids]) < 1e-3 * P**3:
        return None
    prob = n / P
    out, have = [], 0
    while have < m:
        k = min(2 * (m - have) + 1000, 1_000_000)
        x, y, z = (ids[rng.choice(ids.size, k, p=prob)] for _ in range(3))
        ok = (x != y) & (y != z) & (x != z)
        out.append(np.column_stack([np.minimum(x, z), y, np.maximum(x, z)])[ok])
        have += int(ok.sum())
    return np.concatenate(out)[:m]


def _chunk_totals(p: _Pairs) -> tuple[list[int], int]:
    """One pass over the listed triples: every chunk's number of constraints (``sum n_i n_j
    n_k``) and the number of triples."""
    totals, count = [], 0
    for tri in _triple_chunks(p):
        totals.append(int(_triple_weights(p, tri).sum()))
        count += tri.shape[0]
    return totals, count


def _draw_listed(p: _Pairs, m: int, rng, totals: list[int]) -> np.ndarray:
    """``m`` object triples drawn with probability ``n_i n_j n_k / total`` from the listed
    triples (``totals`` per chunk, from :func:`_chunk_totals`), one pass over the chunks
    (memory of one chunk)."""
    per_chunk = rng.multinomial(m, np.array(totals, np.float64) / sum(totals))
    out = []
    for tri, k in zip(_triple_chunks(p), per_chunk):
        if k:
            w = _triple_weights(p, tri).astype(np.float64)
            out.append(np.repeat(tri, rng.multinomial(k, w / w.sum()), axis=0))
    return np.concatenate(out)


def _transitivity_sampled(p: _Pairs, drawn: np.ndarray, total: int, tol: float,
                          rng) -> ConstraintStats:
    """The constraints of one node triple per drawn object triple (nodes uniform): the triples
    are drawn so that every transitivity constraint is equally likely (with replacement)."""
    pid = _pair_index(p)
    flat = p.dense.ravel()
    n = p.dense.shape[1]
    n_bad = 0
    viol = mag = 0.0
    for s in range(0, drawn.shape[0], 500_000):
        i, j, k = drawn[s:s + 500_000].T
        u = rng.integers(0, p.sizes[i])
        v = rng.integers(0, p.sizes[j])
        w = rng.integers(0, p.sizes[k])
        G = (_entries(flat, pid, n, i, j, u, v) + _entries(flat, pid, n, j, k, v, w)
             - _entries(flat, pid, n, i, k, u, w))
        excess = G - 1.0
        bad = excess > tol
        n_bad += int(np.count_nonzero(bad))
        viol += float(excess[bad].sum())
        mag += float(np.abs(G).sum())
    return ConstraintStats(int(total), int(drawn.shape[0]), n_bad, viol, mag, sampled=True)


def _summed(parts) -> ConstraintStats:
    """One :class:`ConstraintStats` of chunks' exhaustive statistics."""
    parts = list(parts)
    return ConstraintStats(sum(t.n_constraints for t in parts), sum(t.n_evaluated for t in parts),
                           sum(t.n_violated for t in parts), sum((t.violation for t in parts), 0.0),
                           sum((t.magnitude for t in parts), 0.0))


def _transitivity(p: _Pairs, max_triples: int, tol: float, rng):
    """Transitivity statistics, the mode used and the number of object triples (each pass
    over the listed triples made once)."""
    if p.dense is None:                        # exact: the evaluating pass counts them too
        parts, count = [], 0
        for tri in _triple_chunks(p):
            parts.append(_transitivity_exact(p, tri))
            count += tri.shape[0]
        return _summed(parts), "exact", count
    complete = _complete_triples(p)
    totals = None
    if complete is not None:                   # counted without listing
        n_tri, total = complete[1], 3 * _elementary3(p.sizes[complete[0]])
    else:
        totals, n_tri = _chunk_totals(p)
        total = sum(totals)
    if total <= max_triples:
        parts = [_transitivity_dense(p, tri, tol) for tri in _triple_chunks(p)]
        return _summed(parts), "exhaustive", n_tri
    rng = as_generator(rng)
    drawn = None if complete is None else _draw_complete(p.sizes, complete[0], max_triples, rng)
    if drawn is None:
        if totals is None:
            totals, _ = _chunk_totals(p)
        drawn = _draw_listed(p, max_triples, rng, totals)
    return _transitivity_sampled(p, drawn, total, tol, rng), "sampled", n_tri


def constraint_violations(X, *, sizes=None, max_triples: int = 1_000_000, tol: float = 1e-9,
                          rng=None) -> ConstraintViolations:
    """Capacity (c1) and transitivity (c2) violations of a multi-matching: CVR, CVVR, ACVV.

    Definitions, what is exact and what is sampled: see :mod:`transync.metrics._constraints`
    (module docstring) and the methods page *Synthetic protocols and evaluation measures*. In
    short, for constraints ``g(x) <= 1``: CVR = violated / constraints, CVVR = sum of ``g(x) - 1``
    over violated / sum of ``|g(x)|``, ACVV = sum of ``g(x) - 1`` over violated / violated.

    Parameters
    ----------
    X : dict, MultiMatching or sequence of 2-d arrays
        *Pairwise* outputs: a dict ``{(i, j): block}`` where a block is an assignment
        (``block[u] = v``, ``-1`` unmatched; injective) or an ``(n_i, n_j)`` matrix (soft or
        0/1; a non-injective rounding must be given as a matrix). The pair ``{i, j}`` is read
        from ``X[(i, j)]`` with ``i < j``, or from ``X[(j, i)]`` transposed when only it is
        given; pairs given in neither direction are unobserved and constrain nothing.
        *Absolute* outputs: a :class:`~transync.permutations.MultiMatching` (or a result with a
        ``.matching``), or one ``(n_i, d)`` map into the universe per object (soft or 0/1),
        from which the blocks ``X_i X_j^T`` of every pair are formed; an ``(N, n, d)`` array
        is ``N`` such maps.
    sizes : sequence of int, optional
        Number of nodes of every object, for pairwise input. Without it, sizes come from the
        matrix shapes and the assignments' lengths; an object seen only as the target of
        assignments gets ``max target + 1`` nodes.
    max_triples : int, default=1_000_000
        Above this many transitivity constraints, inputs that are not partial permutations are
        estimated on ``max_triples`` uniformly sampled node triples (partial permutations are
        always evaluated exactly).
    tol : float, default=1e-9
        A constraint counts as violated when ``g(x) - 1 > tol``.
    rng : None, int or Generator
        Randomness of the sampling.

    Returns
    -------
    ConstraintViolations
        ``capacity`` and ``transitivity`` :class:`ConstraintStats` (``cvr``, ``cvvr``, ``acvv``
        and the counts); ``as_dict()`` for a flat table row.

    Raises
    ------
    ValueError, TypeError
        Malformed blocks or keys, sizes that disagree, maps with different universe sizes.

    Examples
    --------
    >>> import numpy as np
    >>> from transync.permutations import MultiMatching
    >>> m = MultiMatching([np.array([0, 1, 2]), np.array([2, 0]), np.array([1, 2, 0])])
    >>> r = constraint_violations(m)               # consistent by construction
    >>> r.capacity.cvr, r.transitivity.cvr
    (0.0, 0.0)
    >>> noisy = m.pairwise_dict()
    >>> noisy[(0, 2)] = np.array([0, 1, 2])        # rounded on its own: breaks transitivity
    >>> r = constraint_violations(noisy)
    >>> r.transitivity.n_violated, r.transitivity.n_constraints, r.capacity.cvr
    (6, 54, 0.0)
    >>> hard = [np.eye(3)[[0, 0, 1]], np.eye(3)[[2, 0]], np.eye(3)[[1, 2, 0]]]
    >>> constraint_violations(hard).capacity.n_violated    # row argmax: slot 0 taken twice
    1
    """
    check_int(max_triples, "max_triples", minimum=1)
    tol = check_positive(tol, "tol", allow_zero=True)
    if (not isinstance(X, (MultiMatching, Mapping))
            and isinstance(getattr(X, "matching", None), MultiMatching)):
        X = X.matching
    if isinstance(X, np.ndarray) and X.ndim == 3:
        X = list(X)                          # (N, n, d): N absolute maps of one size
    if isinstance(X, Mapping):
        p = _parse_pairwise(X, sizes)
        cap = _pairwise_capacity(p, tol)
        kind = "pairwise"
    elif isinstance(X, MultiMatching) or (isinstance(X, Sequence)
                                          and not isinstance(X, (str, bytes))):
        if sizes is not None:
            raise TypeError("`sizes` is only used with pairwise input (a dict); absolute maps "
                            "carry their sizes")
        p, cap = _parse_absolute(X, tol)
        kind = "absolute"
    else:
        raise TypeError("`X` must be a dict {(i, j): assignment or matrix}, a MultiMatching or "
                        f"a sequence of (n_i, d) maps, got {type(X).__name__}")
    if isinstance(p, _Labels):
        trans, n_pairs, n_tri = _transitivity_labels(p)
        mode = "exact"
    else:
        trans, mode, n_tri = _transitivity(p, max_triples, tol, rng)
        n_pairs = int(p.pairs.shape[0])
    info = {"input": kind, "transitivity_mode": mode, "n_pairs": n_pairs,
            "n_object_triples": int(n_tri)}
    return ConstraintViolations(cap, trans, info)
