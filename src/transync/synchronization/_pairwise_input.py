"""Parsing of pairwise inputs into stacked arrays (private).

Accepted forms of ``pairwise``:

* a mapping ``{(i, j): value}`` with ``i != j`` non-negative ints; ``value`` an assignment index
  array (``value[u] = v``, ``-1`` unmatched) or an ``(n_i, n_j)`` matrix (0/1 for permutations,
  soft for the doubly-stochastic function);
* an iterable of ``(i, j, value)`` triples;
* a dense array of shape ``(N, N, n, n)`` (blocks) or ``(N, N, n)`` (assignments); which pairs are
  used is given by ``mask`` (default: every ``i != j``). Each unordered pair is read once:
  ``[i, j]`` (``i < j``) when ``mask[i, j]``, otherwise ``[j, i]``; every object has ``n`` nodes.

Both ``(i, j)`` and ``(j, i)`` may be given: they are two observations of the same pair, both are
kept (each with its weight) and the block matrix averages them.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from .._validation import check_array, check_int
from ..permutations import check_assignment

__all__: list[str] = []


@dataclass
class StackedPairs:
    """Observations stored as stacked arrays, every pair oriented ``i < j``."""

    n_objects: int
    sizes: np.ndarray            # (N,) int64
    pairs: np.ndarray            # (Q, 2) int64, i < j; an unordered pair may appear twice
    maps: np.ndarray | None      # (Q, n_max) int64 assignment i -> j, -1 unmatched / padding
    soft: np.ndarray | None      # (Q, n_max, n_max) float blocks i -> j (DS input), zero padded
    weights: np.ndarray          # (Q,) float, already divided by the number of observations

    @property
    def n_max(self) -> int:
        return int(self.sizes.max(initial=0))

    @property
    def offsets(self) -> np.ndarray:
        return np.concatenate([[0], np.cumsum(self.sizes)]).astype(np.int64)

    @property
    def is_full(self) -> bool:
        """All objects have the same size and every observed map is a bijection."""
        if self.maps is None or not np.all(self.sizes == self.sizes[0]):
            return False
        return bool(np.all(self.maps[:, : self.sizes[0]] >= 0))


def _items(pairwise, mask):
    """Yield ``(i, j, value)`` from any accepted form."""
    if isinstance(pairwise, Mapping):
        for key, value in pairwise.items():
            if not (isinstance(key, tuple) and len(key) == 2):
                raise ValueError(f"`pairwise` keys must be pairs (i, j), got {key!r}")
            i, j = key
            if mask is not None and not _in_mask(mask, i, j):
                continue
            yield i, j, value
        return
    if isinstance(pairwise, np.ndarray) and pairwise.ndim in (3, 4):
        n = pairwise.shape[0]
        if pairwise.shape[1] != n:
            raise ValueError(f"`pairwise` as an array must have shape (N, N, n[, n]), got "
                             f"{pairwise.shape}")
        if mask is not None and mask.shape != (n, n):
            raise ValueError(f"`mask` must have shape ({n}, {n}) to match `pairwise`, got "
                             f"{mask.shape}")
        m = ~np.eye(n, dtype=bool) if mask is None else (mask & ~np.eye(n, dtype=bool))
        # one read per unordered pair: [i, j] (i < j) where mask[i, j], else [j, i]
        iu, ju = np.nonzero(np.triu(m | m.T, 1))
        for i, j in zip(iu.tolist(), ju.tolist()):
            if m[i, j]:
                yield i, j, pairwise[i, j]
            else:
                yield j, i, pairwise[j, i]
        return
    try:
        it = iter(pairwise)
    except TypeError:
        raise TypeError("`pairwise` must be a dict {(i, j): map}, an iterable of (i, j, map) or "
                        f"an (N, N, n[, n]) array, got {type(pairwise).__name__}") from None
    for item in it:
        if not (isinstance(item, tuple) and len(item) == 3):
            raise ValueError(f"`pairwise` as an iterable must hold (i, j, map) triples, got {item!r}")
        i, j, value = item
        if mask is not None and not _in_mask(mask, i, j):
            continue
        yield i, j, value


def _in_mask(mask, i, j) -> bool:
    i, j = int(i), int(j)
    n = mask.shape[0]
    if not (0 <= i < n and 0 <= j < n):
        raise ValueError(f"`mask` has shape {mask.shape} but `pairwise` holds pair {(i, j)}")
    return bool(mask[i, j] or mask[j, i])


def _weight_of(weights, i, j):
    if weights is None:
        return 1.0
    if isinstance(weights, Mapping):
        if (i, j) in weights:
            return weights[(i, j)]
        if (j, i) in weights:
            return weights[(j, i)]
        raise ValueError(f"`weights` has no entry for pair {(i, j)}")
    return weights[i, j]


def parse_pairwise(pairwise, *, mask=None, weights=None, sizes=None, soft: bool = False,
                   name: str = "pairwise") -> StackedPairs:
    """Validate ``pairwise`` and stack it. ``soft=True`` keeps matrices as float blocks."""
    if mask is not None:
        mask = check_array(mask, "mask", ndim=2, dtype=bool)
        if mask.shape[0] != mask.shape[1]:
            raise ValueError(f"`mask` must be a square (N, N) array, got shape {mask.shape}")
    if weights is not None and not isinstance(weights, Mapping):
        weights = check_array(weights, "weights", ndim=2)
        if weights.shape[0] != weights.shape[1]:
            raise ValueError(f"`weights` must be a square (N, N) array or a dict, got shape "
                             f"{weights.shape}")
    fixed = None
    if sizes is None and isinstance(pairwise, np.ndarray) and pairwise.ndim in (3, 4):
        sizes = np.full(pairwise.shape[0], pairwise.shape[2], dtype=np.int64)
    if sizes is not None:
        fixed = np.asarray(sizes)
        if fixed.ndim != 1 or fixed.dtype.kind not in "iu" or (fixed.size and fixed.min() < 1):
            raise ValueError(f"`sizes` must be a 1-d array of positive ints, got {sizes!r}")
        fixed = fixed.astype(np.int64)

    keys_i: list[int] = []
    keys_j: list[int] = []
    vals: list[np.ndarray] = []
    if isinstance(pairwise, Mapping) and mask is None:
        raw_keys = list(pairwise.keys())
        vals = [np.asarray(v) for v in pairwise.values()]
        karr = np.array(raw_keys, dtype=object) if raw_keys else np.zeros((0, 2))
        try:
            karr = np.array(raw_keys)
        except ValueError:
            karr = None
        if karr is not None and karr.ndim == 2 and karr.shape[1] == 2 and karr.dtype.kind in "iu":
            keys_i = karr[:, 0].tolist()
            keys_j = karr[:, 1].tolist()
        else:
            for key in raw_keys:
                if not (isinstance(key, tuple) and len(key) == 2):
                    raise ValueError(f"`{name}` keys must be pairs (i, j), got {key!r}")
                try:
                    keys_i.append(check_int(key[0], f"{name} key"))
                    keys_j.append(check_int(key[1], f"{name} key"))
                except TypeError:
                    raise TypeError(f"`{name}` keys must be pairs of ints, got {key!r}") from None
    else:
        for i, j, value in _items(pairwise, mask):
            try:
                i = check_int(i, f"{name} key"); j = check_int(j, f"{name} key")  # noqa: E702
            except TypeError:
                raise TypeError(f"`{name}` keys must be pairs of ints, got {(i, j)!r}") from None
            keys_i.append(i); keys_j.append(j); vals.append(np.asarray(value))  # noqa: E702
    if not vals:
        raise ValueError(f"`{name}` must contain at least one observed pair i != j")
    ki_arr = np.asarray(keys_i, dtype=np.int64)
    kj_arr = np.asarray(keys_j, dtype=np.int64)
    if ki_arr.min() < 0 or kj_arr.min() < 0:
        q = int(np.flatnonzero((ki_arr < 0) | (kj_arr < 0))[0])
        raise ValueError(f"`{name}` keys must be non-negative object indices, got "
                         f"{(keys_i[q], keys_j[q])}")
    if np.any(ki_arr == kj_arr):
        q = int(np.flatnonzero(ki_arr == kj_arr)[0])
        raise ValueError(f"`{name}` must not contain pairs with i == j, got "
                         f"{(keys_i[q], keys_j[q])}")
    for q, arr in enumerate(vals):
        if arr.ndim not in (1, 2):
            raise ValueError(f"`{name}[{(keys_i[q], keys_j[q])}]` must be an assignment (1-d) or "
                             f"a matrix (2-d), got shape {arr.shape}")
    is_matrix = [arr.ndim == 2 for arr in vals]
    if weights is None:
        ws = np.ones(len(vals))
    elif isinstance(weights, Mapping):
        ws = np.array([float(_weight_of(weights, i, j)) for i, j in zip(keys_i, keys_j)])
    else:
        if max(ki_arr.max(), kj_arr.max()) >= weights.shape[0]:
            raise ValueError(f"`weights` must be ({int(max(ki_arr.max(), kj_arr.max())) + 1}, ...) "
                             f"or larger, got shape {weights.shape}")
        ws = weights[ki_arr, kj_arr].astype(float)
    if np.any(~np.isfinite(ws)) or np.any(ws < 0):
        q = int(np.flatnonzero(~np.isfinite(ws) | (ws < 0))[0])
        raise ValueError(f"`weights` must be finite and >= 0, got {ws[q]!r} for pair "
                         f"{(keys_i[q], keys_j[q])}")

    ki, kj = ki_arr, kj_arr
    n_obj = int(max(ki.max(), kj.max())) + 1
    if fixed is not None:
        if fixed.size < n_obj:
            raise ValueError(f"`sizes` must have an entry for every object (>= {n_obj}), got "
                             f"{fixed.size}")
        n_obj = fixed.size
    if mask is not None:
        n_obj = max(n_obj, mask.shape[0])

    # sizes: exact from lengths / matrix shapes, lower bounds from targets
    exact = np.full(n_obj, -1, dtype=np.int64) if fixed is None else fixed.copy()
    lower = np.zeros(n_obj, dtype=np.int64)
    stacked = None

    def _set_exact(g, value, what):
        if exact[g] >= 0 and exact[g] != value:
            raise ValueError(f"`{name}`: mismatched sizes for object {g}: {what} has size "
                             f"{value} but object {g} has {exact[g]} nodes elsewhere")
        exact[g] = value

    if not any(is_matrix):
        lens = np.fromiter((a.shape[0] for a in vals), dtype=np.int64, count=len(vals))
        stacked = None
        if lens.min() == lens.max() and all(a.dtype.kind in "iu" for a in vals):
            stacked = np.stack(vals).astype(np.int64, copy=False)
            maxs = stacked.max(1) if stacked.shape[1] else np.full(len(vals), -1)
        else:
            maxs = np.fromiter((int(np.max(a)) if a.size else -1 for a in vals),
                               dtype=np.int64, count=len(vals))
        order = np.argsort(ki_arr, kind="stable")
        ks, ls = ki_arr[order], lens[order]
        first = np.r_[True, ks[1:] != ks[:-1]]
        grp_len = ls[first]
        grp_obj = ks[first]
        # every occurrence of an object as a source must have the same length
        bad = np.flatnonzero(ls != np.repeat(grp_len, np.diff(np.r_[np.flatnonzero(first), ks.size])))
        if bad.size:
            g = int(ks[bad[0]])
            raise ValueError(f"`{name}`: mismatched sizes for object {g}: its assignments have "
                             f"lengths {sorted(set(ls[ks == g].tolist()))}")
        for g, n_g in zip(grp_obj.tolist(), grp_len.tolist()):
            _set_exact(g, n_g, "an assignment")
        np.maximum.at(lower, kj_arr, maxs + 1)
    else:
        for i, j, arr, mat in zip(keys_i, keys_j, vals, is_matrix):
            if mat:
                _set_exact(i, arr.shape[0], f"pair {(i, j)} (rows)")
                _set_exact(j, arr.shape[1], f"pair {(i, j)} (columns)")
            else:
                _set_exact(i, arr.shape[0], f"pair {(i, j)}")
                if arr.size:
                    lower[j] = max(lower[j], int(np.max(arr)) + 1)
    sizes_out = np.where(exact >= 0, exact, np.maximum(lower, 0))
    bad = np.flatnonzero((exact >= 0) & (lower > exact))
    if bad.size:
        g = int(bad[0])
        raise ValueError(f"`{name}`: mismatched sizes: some map targets node {lower[g] - 1} of "
                         f"object {g}, which has only {exact[g]} nodes")
    empty = np.flatnonzero(sizes_out == 0)
    if empty.size:
        raise ValueError(f"`{name}`: cannot infer the size of object(s) {empty.tolist()[:5]}; "
                         "pass `sizes=`")
    n_max = int(sizes_out.max())

    Q = len(vals)
    pairs = np.column_stack([np.minimum(ki, kj), np.maximum(ki, kj)])
    flip = ki > kj
    maps = None
    soft_blocks = None
    if soft:
        soft_blocks = np.zeros((Q, n_max, n_max))
        for q, (i, j, arr, mat) in enumerate(zip(keys_i, keys_j, vals, is_matrix)):
            if mat:
                block = check_array(arr, f"{name}[{(i, j)}]", ndim=2)
            else:
                a = check_assignment(arr, f"{name}[{(i, j)}]", n2=sizes_out[j])
                block = np.zeros((sizes_out[i], sizes_out[j]))
                r = np.flatnonzero(a >= 0)
                block[r, a[r]] = 1.0
            if flip[q]:
                block = block.T
            soft_blocks[q, : block.shape[0], : block.shape[1]] = block
    else:
        maps = np.full((Q, n_max), -1, dtype=np.int64)
        if stacked is not None and stacked.shape[1] == n_max:
            if stacked.min() < -1:
                raise ValueError(f"`{name}` assignments must hold entries >= -1, got "
                                 f"{int(stacked.min())}")
            tgt_size = sizes_out[kj]
            if np.any(stacked >= tgt_size[:, None]):
                q = int(np.flatnonzero((stacked >= tgt_size[:, None]).any(1))[0])
                raise ValueError(f"`{name}[{(keys_i[q], keys_j[q])}]` targets a node beyond "
                                 f"object {keys_j[q]}'s {tgt_size[q]} nodes")
            srt = np.sort(stacked, axis=1)
            dup = (srt[:, 1:] == srt[:, :-1]) & (srt[:, 1:] >= 0)
            if dup.any():
                q = int(np.flatnonzero(dup.any(1))[0])
                raise ValueError(f"`{name}[{(keys_i[q], keys_j[q])}]` must be injective (a "
                                 "partial permutation): a target node is used twice")
            maps[:] = stacked
        else:
            for q, (i, j, arr, mat) in enumerate(zip(keys_i, keys_j, vals, is_matrix)):
                label = f"{name}[{(i, j)}]"
                if mat:
                    M = check_array(arr, label, ndim=2)
                    if not _is_partial_perm(M):
                        raise ValueError(
                            f"`{label}` must be a 0/1 partial-permutation matrix (at most one 1 "
                            "per row and column); for soft matrices use "
                            "synchronize_doubly_stochastic or round them with solve_lap")
                    a = np.full(M.shape[0], -1, dtype=np.int64)
                    r, c = np.nonzero(M > 0.5)
                    a[r] = c
                else:
                    a = check_assignment(arr, label, n2=sizes_out[j])
                maps[q, : a.shape[0]] = a
        if flip.any():
            for q in np.flatnonzero(flip):
                i, j = int(ki[q]), int(kj[q])
                a = maps[q, : sizes_out[i]]
                inv = np.full(n_max, -1, dtype=np.int64)
                r = np.flatnonzero(a >= 0)
                inv[a[r]] = r
                maps[q] = inv
    # average duplicated observations of the same unordered pair
    w = np.asarray(ws, dtype=float).copy()
    key = pairs[:, 0] * n_obj + pairs[:, 1]
    _, inverse, counts = np.unique(key, return_inverse=True, return_counts=True)
    w = w / counts[inverse]
    return StackedPairs(n_objects=n_obj, sizes=sizes_out.astype(np.int64), pairs=pairs,
                        maps=maps, soft=soft_blocks, weights=w)


def _is_partial_perm(M: np.ndarray, atol: float = 1e-8) -> bool:
    binary = np.all((np.abs(M) <= atol) | (np.abs(M - 1) <= atol))
    return bool(binary and np.all(M.sum(0) <= 1 + atol) and np.all(M.sum(1) <= 1 + atol))
