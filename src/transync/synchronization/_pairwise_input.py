"""The one parser of pairwise inputs for every synchronization function (private).

Accepted forms of ``pairwise`` (permutations and soft matchings) and of ``T`` (linear maps):

* a mapping ``{(i, j): value}`` with ``i != j`` non-negative ints;
* an iterable of ``(i, j, value)`` triples;
* a dense array ``(N, N, ...)`` whose entry ``[i, j]`` is the observation of pair ``(i, j)``.

Values of permutation inputs are assignments (``value[u] = v``, ``-1`` unmatched; validated by
:func:`transync.permutations.check_assignment`) or ``(n_i, n_j)`` matrices (0/1 for
permutations, converted by :func:`transync.permutations.matrix_to_assignment`; soft for the
doubly-stochastic function). Linear maps are ``(d, d)`` matrices.

``mask`` -- one meaning everywhere
----------------------------------
``mask`` is an ``(N, N)`` boolean (or 0/1) array (its diagonal is ignored) that selects the
*pairs* to use: the pair ``{i, j}`` is used when ``mask[i, j] or mask[j, i]``. It only filters:
every observation given for a selected pair is kept, observations of other pairs are ignored,
whatever the form of the input (dict, triples or dense array). A dense array is read at the
selected pairs: permutation arrays once per pair (``[i, j]`` with ``i < j`` when
``mask[i, j]``, else ``[j, i]``: the two directions of a permutation carry the same
information), linear-map arrays in every direction whose mask entry is True (a direction left out
is the inverse of the other). ``mask=None`` selects every pair ``i != j``. A mask that selects
none of the observed pairs is an error.

Both ``(i, j)`` and ``(j, i)`` may be given: they are two observations of the same pair, both are
kept (each with its weight) and the block matrix averages them.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from .._validation import MAX_AFFINITY_SCALE, check_array, check_int, check_int_array, short_repr
from ..permutations import (
    MAX_NODES,
    assignment_to_matrix,
    check_assignment,
    first_invalid_assignment,
    matrix_to_assignment,
)

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


# ----------------------------------------------------------------------------------------------
# shared pieces: mask, universe, keys
# ----------------------------------------------------------------------------------------------

def check_mask(mask, n: int | None = None, *, against: str = "pairwise") -> np.ndarray | None:
    """Validate ``mask``: square, boolean or 0/1, ``(n, n)`` if given; the diagonal is ignored."""
    if mask is None:
        return None
    if isinstance(mask, (Mapping, set, frozenset)):
        raise TypeError(f"`mask` must be an (N, N) boolean array (True where the pair is "
                        f"used), got {type(mask).__name__}")
    arr = check_array(mask, "mask", ndim=2, dtype=None, finite=False)
    if arr.dtype != bool:
        if arr.dtype.kind not in "iuf" or not np.all(np.isin(arr, (0, 1))):
            raise ValueError(f"`mask` must be boolean (or 0/1), got dtype {arr.dtype}")
        arr = arr.astype(bool)
    if arr.shape[0] != arr.shape[1]:
        raise ValueError(f"`mask` must be a square (N, N) array, got shape {arr.shape}")
    if n is not None and arr.shape != (n, n):
        raise ValueError(f"`mask` must have shape ({n}, {n}) to match `{against}`, got shape "
                         f"{arr.shape}")
    arr = arr.copy()
    np.fill_diagonal(arr, False)             # self-pairs carry no information: ignored
    return arr


def mask_selects(mask: np.ndarray, i: int, j: int, *, name: str = "pairwise") -> bool:
    """Whether ``mask`` selects the pair ``{i, j}`` (``mask[i, j] or mask[j, i]``)."""
    n = mask.shape[0]
    if not (0 <= i < n and 0 <= j < n):
        raise ValueError(f"`mask` has shape {mask.shape} but `{name}` holds pair {(i, j)}")
    return bool(mask[i, j] or mask[j, i])


def check_universe(n_universe, sizes: np.ndarray) -> int | None:
    """``max n_g <= n_universe <= sum n_g``: a slot that no node can fill is never needed."""
    if n_universe is None:
        return None
    n_universe = check_int(n_universe, "n_universe", minimum=1)
    n_max, total = int(sizes.max()), int(sizes.sum())
    if n_universe < n_max:
        raise ValueError(f"`n_universe` must be >= the largest object size {n_max}, got "
                         f"{n_universe}")
    if n_universe > total:
        raise ValueError(f"`n_universe` must be <= the total number of nodes {total} (every "
                         f"universe slot holds at least one node), got {n_universe}")
    return n_universe


def _key(i, j, name: str) -> tuple[int, int]:
    try:
        i = check_int(i, f"{name} key")
        j = check_int(j, f"{name} key")
    except TypeError:
        raise TypeError(f"`{name}` keys must be pairs of ints, got {(i, j)!r}") from None
    if i < 0 or j < 0:
        raise ValueError(f"`{name}` keys must be non-negative object indices, got {(i, j)}")
    if max(i, j) >= 2**62:                      # stored as int64
        raise ValueError(f"`{name}` keys must be object indices below 2**62, got "
                         f"{short_repr((i, j))}")
    if i == j:
        raise ValueError(f"`{name}` must not contain pairs with i == j (self-pairs), got "
                         f"{(i, j)}")
    return i, j


def observations(pairwise, mask, *, name: str = "pairwise", dense_both: bool = False):
    """``[(i, j, value)]`` of the observations of the selected pairs, from any accepted form.

    ``dense_both``: read a dense array in every masked direction (linear maps) instead of once
    per pair (permutations). Keys are validated (ints, non-negative, ``i != j``).
    """
    out = []
    if isinstance(pairwise, Mapping):
        out = _mapping_observations(pairwise, name)
    elif isinstance(pairwise, np.ndarray) and pairwise.ndim >= 3:
        return _dense_observations(pairwise, mask, name=name, dense_both=dense_both)
    elif isinstance(pairwise, np.ndarray) and pairwise.dtype != object:
        raise ValueError(f"`{name}` as an array must have shape (N, N, ...), one map per pair "
                         f"of objects, got shape {pairwise.shape}")
    else:
        if isinstance(pairwise, (str, bytes)) or not hasattr(pairwise, "__iter__"):
            raise TypeError(f"`{name}` must be a dict {{(i, j): map}}, an iterable of (i, j, map) "
                            f"or an (N, N, ...) array, got {type(pairwise).__name__}")
        for item in pairwise:
            if not (isinstance(item, tuple) and len(item) == 3):
                raise ValueError(f"`{name}` as an iterable must hold (i, j, map) triples, got "
                                 f"{item!r:.80}")
            out.append((*_key(item[0], item[1], name), item[2]))
    if mask is not None:
        kept = [o for o in out if mask_selects(mask, o[0], o[1], name=name)]
        if out and not kept:
            raise ValueError(f"`mask` selects none of the {len(out)} observed pairs of `{name}`")
        out = kept
    return out


def _mapping_observations(pairwise: Mapping, name: str) -> list:
    keys = list(pairwise.keys())
    if keys and all(type(k) is tuple and len(k) == 2 for k in keys):
        try:
            karr = np.array(keys)
        except (TypeError, ValueError, OverflowError):
            karr = None
        if karr is not None and karr.ndim == 2 and karr.dtype.kind in "iu":
            bad = np.flatnonzero((karr < 0).any(1) | (karr[:, 0] == karr[:, 1])
                                 | (karr >= 2**62).any(1))
            if not bad.size:                             # fast path: valid int keys
                return [(int(i), int(j), v)
                        for (i, j), v in zip(karr.tolist(), pairwise.values())]
    out = []
    for key, value in pairwise.items():
        if not (isinstance(key, tuple) and len(key) == 2):
            raise ValueError(f"`{name}` keys must be pairs (i, j), got {key!r}")
        out.append((*_key(*key, name), value))
    return out


def _dense_observations(arr, mask, *, name, dense_both):
    n = arr.shape[0]
    if arr.shape[1] != n:
        raise ValueError(f"`{name}` as an array must have shape (N, N, ...), got {arr.shape}")
    if mask is not None and mask.shape != (n, n):
        raise ValueError(f"`mask` must have shape ({n}, {n}) to match `{name}`, got "
                         f"{mask.shape}")
    m = ~np.eye(n, dtype=bool) if mask is None else mask
    if dense_both:
        return [(i, j, arr[i, j]) for i, j in zip(*np.nonzero(m))]
    iu, ju = np.nonzero(np.triu(m | m.T, 1))
    return [(i, j, arr[i, j]) if m[i, j] else (j, i, arr[j, i])
            for i, j in zip(iu.tolist(), ju.tolist())]


# ----------------------------------------------------------------------------------------------
# permutations and soft matchings
# ----------------------------------------------------------------------------------------------

def parse_pairwise(pairwise, *, mask=None, weights=None, sizes=None, soft: bool = False,
                   name: str = "pairwise") -> StackedPairs:
    """Validate ``pairwise`` and stack it. ``soft=True`` keeps matrices as float blocks."""
    mask = check_mask(mask)
    weights = _check_weights_arg(weights)
    fixed = _check_sizes_arg(sizes, pairwise)
    ki, kj, raw = _observation_arrays(pairwise, mask, name)
    if not raw and mask is not None:
        raise ValueError(f"`mask` selects no pair of `{name}`")
    if not raw:
        raise ValueError(f"`{name}` must contain at least one observed pair i != j")
    vals = _as_values(ki, kj, raw, soft, name)
    ws = pair_weights(weights, ki, kj)
    if not (ws > 0).any():          # weight 0 = not observed: every object would stand alone
        raise ValueError(f"`weights` are 0 on all {ws.size} observed pair(s) of `{name}`, so no "
                         "pair links two objects; give at least one pair a positive weight")
    n_obj = _count_objects(ki, kj, fixed, mask, name)
    check_weight_keys(weights, n_obj)
    sizes_out = _infer_sizes(ki, kj, vals, fixed, n_obj, name)
    _check_working_set(ki.size, sizes_out, soft, name)
    check_weight_magnitude(ws, int(sizes_out.max(initial=1)))
    pairs = np.column_stack([np.minimum(ki, kj), np.maximum(ki, kj)])
    if soft:
        maps, blocks = None, _stack_soft(ki, kj, vals, sizes_out)
    else:
        maps, blocks = _stack_maps(ki, kj, vals, sizes_out, name), None
    # average duplicated observations of the same unordered pair
    key = pairs[:, 0] * n_obj + pairs[:, 1]
    _, inverse, counts = np.unique(key, return_inverse=True, return_counts=True)
    return StackedPairs(n_objects=n_obj, sizes=sizes_out, pairs=pairs, maps=maps, soft=blocks,
                        weights=ws / counts[inverse])


#: Entries of the largest dense array the synchronizers build from the input: the stacked maps
#: (pairs x n_max, soft: pairs x n_max^2) and the embedding (total nodes x n_max, at least the
#: universe). 2**31 entries are 16 GiB; above it the input is refused up front instead of a
#: MemoryError or minutes of allocation (sizes [2, 10**7] asked for 728 TiB). NCI1's 8.4 million
#: pairs of graphs padded to 111 nodes (the kernels' all-pairs run) need 9.3e8.
MAX_WORKING_ENTRIES = 2**31


def _check_working_set(n_pairs: int, sizes: np.ndarray, soft: bool, name: str) -> None:
    n_max, total = int(sizes.max(initial=1)), int(sizes.sum())
    need = {"the stacked pairs": n_pairs * n_max * (n_max if soft else 1),
            "the embedding (total nodes x largest object)": total * n_max}
    what, entries = max(need.items(), key=lambda kv: kv[1])
    if entries > MAX_WORKING_ENTRIES:
        raise ValueError(f"`{name}` describes {sizes.size} objects, the largest of {n_max} "
                         f"nodes ({total} in all, from `sizes` or the maps' entries): "
                         f"{what} would be a dense array of {entries:.3g} entries, above "
                         f"{MAX_WORKING_ENTRIES:.3g}; synchronize fewer or smaller objects")


def _check_weights_arg(weights):
    if weights is None or isinstance(weights, Mapping):
        return weights
    weights = check_array(weights, "weights", ndim=2)
    if weights.shape[0] != weights.shape[1]:
        raise ValueError(f"`weights` must be a square (N, N) array or a dict, got shape "
                         f"{weights.shape}")
    if weights.size and weights.min() < 0:
        raise ValueError(f"`weights` must be finite and >= 0, got {float(weights.min())}")
    return weights


def _check_sizes_arg(sizes, pairwise):
    if sizes is None and isinstance(pairwise, np.ndarray) and pairwise.ndim in (3, 4):
        sizes = np.full(pairwise.shape[0], pairwise.shape[2], dtype=np.int64)
    if sizes is None:
        return None
    fixed = check_array(sizes, "sizes", dtype=None)     # not complex, NaN, infinite
    fixed = check_int_array(fixed, "sizes", integral_floats=True, copy=True)  # 2.0 is a size
    if fixed.ndim != 1 or (fixed.size and fixed.min() < 1):
        raise ValueError(f"`sizes` must be a 1-d array of positive ints, got {sizes!r:.80}")
    if fixed.size and fixed.max() > MAX_NODES:
        raise ValueError(f"`sizes` must be <= {MAX_NODES} nodes per object, got "
                         f"{int(fixed.max())}")
    return fixed


@dataclass
class _Values:
    """Validated values: ``items[q] = (array, n_columns)`` (an int64 assignment, ``n_columns``
    None or the column count of the 0/1 matrix it came from; a float matrix with ``soft``), and
    ``stacked`` ``(Q, n)`` when every value is an assignment of the same length ``n``."""

    items: list | None
    stacked: np.ndarray | None = None


def _observation_arrays(pairwise, mask, name):
    """``(ki, kj, values)`` of the selected observations; dicts with int keys vectorized."""
    if isinstance(pairwise, Mapping):
        keys = _int_keys(pairwise)
        if keys is not None:
            ki, kj = keys
            raw = list(pairwise.values())
            if mask is not None and ki.size:
                top = np.maximum(ki, kj)
                if top.max() >= mask.shape[0]:
                    q = int(np.flatnonzero(top >= mask.shape[0])[0])
                    raise ValueError(f"`mask` has shape {mask.shape} but `{name}` holds pair "
                                     f"{(int(ki[q]), int(kj[q]))}")
                idx = np.flatnonzero(mask[ki, kj] | mask[kj, ki])
                if not idx.size:
                    raise ValueError(f"`mask` selects none of the {ki.size} observed pairs of "
                                     f"`{name}`")
                ki, kj, raw = ki[idx], kj[idx], [raw[q] for q in idx.tolist()]
            return ki, kj, raw
    obs = observations(pairwise, mask, name=name)
    return (np.array([o[0] for o in obs], dtype=np.int64),
            np.array([o[1] for o in obs], dtype=np.int64), [o[2] for o in obs])


def _int_keys(pairwise: Mapping):
    """Keys as two int arrays when all are valid ``(i, j)`` int pairs, else None."""
    keys = list(pairwise.keys())
    if not keys or not all(type(k) is tuple and len(k) == 2 for k in keys):
        return None
    try:
        karr = np.array(keys)
    except (TypeError, ValueError, OverflowError):    # ints beyond int64: the slow path names them
        return None
    if karr.ndim != 2 or karr.dtype.kind not in "iu":
        return None
    if np.any((karr < 0).any(1) | (karr[:, 0] == karr[:, 1]) | (karr >= 2**62).any(1)):
        return None                                  # the slow path names the bad key
    karr = karr.astype(np.int64)
    return karr[:, 0].copy(), karr[:, 1].copy()


def _as_values(ki, kj, raw, soft: bool, name: str) -> _Values:
    """Validate every value (assignments by ``check_assignment``, 0/1 matrices by
    ``matrix_to_assignment``, soft ones by ``check_array``); 1-d int arrays all at once."""
    if not soft and all(isinstance(v, np.ndarray) and v.ndim == 1 and v.dtype.kind == "i"
                        for v in raw):
        lengths = np.fromiter((v.shape[0] for v in raw), np.int64, len(raw))
        flat = np.concatenate(raw).astype(np.int64, copy=False)
        q = first_invalid_assignment(flat, lengths)
        if q == -1 and (lengths == lengths[0]).all():
            return _Values(None, flat.reshape(len(raw), int(lengths[0])))
        if q == -1:
            return _Values([(a, None) for a in np.split(flat, np.cumsum(lengths)[:-1])])
        if q is not None:
            check_assignment(raw[q], f"{name}[{(int(ki[q]), int(kj[q]))}]")        # raises
    return _Values([_as_value(v, f"{name}[{(i, j)}]", soft)
                    for i, j, v in zip(ki.tolist(), kj.tolist(), raw)])


def _as_value(value, label: str, soft: bool) -> tuple[np.ndarray, int | None]:
    if isinstance(value, (str, bytes)) or value is None or sp.issparse(value):
        raise TypeError(f"`{label}` must be an assignment or a dense matrix, got "
                        f"{type(value).__name__}")
    try:
        arr = np.asarray(value)
    except (TypeError, ValueError):                 # ragged nesting
        raise ValueError(f"`{label}` must be an assignment (1-d) or a matrix (2-d) of one row "
                         f"length, got rows of different lengths") from None
    if arr.ndim == 1:
        return check_assignment(arr, label), None
    if arr.ndim != 2:
        raise ValueError(f"`{label}` must be an assignment (1-d) or a matrix (2-d), got shape "
                         f"{arr.shape}")
    if soft:
        return check_array(arr, label, ndim=2), arr.shape[1]
    return matrix_to_assignment(arr, name=label), arr.shape[1]


def pair_weights(weights, ki, kj) -> np.ndarray:
    """The weights of the observed pairs ``(ki[q], kj[q])``: all ones for None, else read from
    an (N, N) array or a dict ``{(i, j): w}`` (either direction; an observed pair without an
    entry is an error), checked finite and non-negative."""
    if weights is None:
        return np.ones(ki.size)
    if isinstance(weights, Mapping):
        ws = []
        for i, j in zip(ki.tolist(), kj.tolist()):
            if (i, j) in weights:
                w = weights[(i, j)]
            elif (j, i) in weights:
                w = weights[(j, i)]
            else:
                raise ValueError(f"`weights` has no entry for pair {(i, j)}")
            ws.append(check_array(w, f"weights[{(i, j)}]", ndim=0, finite=False))
        ws = np.array(ws, dtype=float)
    else:
        top = int(max(ki.max(), kj.max()))
        if top >= weights.shape[0]:
            raise ValueError(f"`weights` must be ({top + 1}, {top + 1}) or larger, got shape "
                             f"{weights.shape}")
        ws = weights[ki, kj].astype(float)
    bad = np.flatnonzero(~np.isfinite(ws) | (ws < 0))
    if bad.size:
        q = int(bad[0])
        raise ValueError(f"`weights` must be finite and >= 0, got {float(ws[q])} for pair "
                         f"{(int(ki[q]), int(kj[q]))}")
    return ws


def check_weight_keys(weights, n_objects: int) -> None:
    """Refuse a dict of weights with a key that names no pair of the ``n_objects`` objects
    (not an ``(i, j)`` pair of ints, negative, ``i == j`` or an index ``>= n_objects``): a typo
    in a key was ignored. Keys of pairs that are not observed are allowed (and unused)."""
    if not isinstance(weights, Mapping):
        return
    for key in weights:
        if not isinstance(key, tuple) or len(key) != 2:
            raise TypeError(f"`weights` keys must be (i, j) pairs of object indices, got "
                            f"{short_repr(key, 40)}")
        i, j = _key(*key, "weights")
        if max(i, j) >= n_objects:
            raise ValueError(f"`weights` key {(i, j)} names object {max(i, j)}, but the input has "
                             f"{n_objects} objects (indices 0..{n_objects - 1})")


def check_weight_magnitude(ws: np.ndarray, per_pair: int) -> None:
    """Refuse pair weights ``ws`` whose largest times the observed entries (``per_pair`` per
    pair: a bound on every objective and block-matrix row sum) overflows float64; only the
    weights' ratios matter, so rescaling them is free."""
    top = float(ws.max()) if ws.size else 0.0
    entries = max(ws.size * max(per_pair, 1), 1)
    if top > MAX_AFFINITY_SCALE / entries:
        raise ValueError(f"`weights` are too large: the largest, {top:.3g}, times the {entries} "
                         f"observed entries exceeds {MAX_AFFINITY_SCALE:g} (the objective would "
                         f"overflow float64); only their ratios matter, so rescale them")


def _count_objects(ki, kj, fixed, mask, name) -> int:
    """Number of objects; every object without an observation needs ``sizes``."""
    n_obj = int(max(ki.max(), kj.max())) + 1
    if fixed is not None:
        if fixed.size < n_obj:
            raise ValueError(f"`sizes` must have an entry for every object (>= {n_obj}), got "
                             f"{fixed.size}")
        return int(fixed.size)
    if mask is not None:
        n_obj = max(n_obj, mask.shape[0])
    seen = np.unique(np.concatenate([ki, kj]))
    if seen.size < n_obj:
        missing = np.setdiff1d(np.arange(min(n_obj, seen.size + 6)), seen)[:5]
        raise ValueError(f"`{name}`: cannot infer the size of object(s) {missing.tolist()} "
                         f"(objects 0 .. {n_obj - 1}, {n_obj - seen.size} of them in no pair); "
                         "pass `sizes=` or renumber the objects")
    return n_obj


def _infer_sizes(ki, kj, vals, fixed, n_obj, name) -> np.ndarray:
    """Object sizes: exact from lengths / matrix shapes, lower bounds from targets (vectorized
    over the observations; the first conflict in input order is reported)."""
    Q = ki.size
    if vals.stacked is not None:
        n = vals.stacked.shape[1]
        lens = np.full(Q, n, dtype=np.int64)
        cols = np.full(Q, -1, dtype=np.int64)
        tops = vals.stacked.max(1) if n else np.full(Q, -1, dtype=np.int64)
    else:
        lens = np.fromiter((a.shape[0] for a, _ in vals.items), dtype=np.int64, count=Q)
        cols = np.fromiter((-1 if n2 is None else n2 for _, n2 in vals.items), dtype=np.int64,
                           count=Q)
        tops = np.fromiter((int(a.max()) if n2 is None and a.size else -1
                            for a, n2 in vals.items), dtype=np.int64, count=Q)
    mat = cols >= 0
    # every (object, size) claim: rows of every observation, columns of matrices
    obj = np.concatenate([ki, kj[mat]])
    size = np.concatenate([lens, cols[mat]])
    src = np.concatenate([np.arange(Q), np.flatnonzero(mat)])
    if fixed is not None:
        ref = fixed[obj]
    else:
        first = np.full(n_obj, -1, dtype=np.int64)
        order = np.lexsort((src, obj))[::-1]              # earliest claim of each object wins
        first[obj[order]] = size[order]
        ref = first[obj]
    bad = np.flatnonzero(size != ref)
    if bad.size:
        c = bad[np.argmin(src[bad])]
        q, g = int(src[c]), int(obj[c])
        raise ValueError(f"`{name}`: mismatched sizes for object {g}: pair "
                         f"{(int(ki[q]), int(kj[q]))} gives it {int(size[c])} nodes but object "
                         f"{g} has {int(ref[c])} nodes elsewhere")
    exact = np.full(n_obj, -1, dtype=np.int64) if fixed is None else fixed.copy()
    exact[obj] = size
    lower = np.zeros(n_obj, dtype=np.int64)
    np.maximum.at(lower, kj, tops + 1)
    over = np.flatnonzero((exact[kj] >= 0) & (tops >= exact[kj]))
    if over.size:
        q = int(over[0])
        g = int(kj[q])
        raise ValueError(f"`{name}[{(int(ki[q]), g)}]` targets node {int(tops[q])}, beyond "
                         f"object {g}'s {int(exact[g])} nodes (mismatched sizes)")
    sizes_out = np.where(exact >= 0, exact, lower)
    empty = np.flatnonzero(sizes_out == 0)
    if empty.size:
        raise ValueError(f"`{name}`: cannot infer the size of object(s) {empty.tolist()[:5]} "
                         "(no node is ever matched); pass `sizes=`")
    return sizes_out.astype(np.int64)


def _stack_soft(ki, kj, vals, sizes) -> np.ndarray:
    n_max = int(sizes.max())
    blocks = np.zeros((ki.size, n_max, n_max))
    for q, (i, j, (arr, _)) in enumerate(zip(ki.tolist(), kj.tolist(), vals.items)):
        block = arr if arr.ndim == 2 else assignment_to_matrix(arr, int(sizes[j]))
        if i > j:
            block = block.T
        blocks[q, : block.shape[0], : block.shape[1]] = block
    return blocks


def _stack_maps(ki, kj, vals, sizes, name) -> np.ndarray:
    """(Q, n_max) maps oriented ``min -> max``; targets checked against the object sizes."""
    n_max = int(sizes.max())
    maps = np.full((ki.size, n_max), -1, dtype=np.int64)
    if vals.stacked is not None:
        maps[:, : vals.stacked.shape[1]] = vals.stacked
    else:
        for q, (arr, _) in enumerate(vals.items):
            maps[q, : arr.shape[0]] = arr
    tgt = sizes[kj][:, None]
    beyond = maps >= tgt
    if beyond.any():
        q = int(np.flatnonzero(beyond.any(1))[0])
        raise ValueError(f"`{name}[{(int(ki[q]), int(kj[q]))}]` targets node "
                         f"{int(maps[q].max())}, beyond object {int(kj[q])}'s {int(tgt[q, 0])} "
                         "nodes")
    for q in np.flatnonzero(ki > kj):                     # store as the inverse map j -> i
        a = maps[q, : sizes[ki[q]]]
        inv = np.full(n_max, -1, dtype=np.int64)
        r = np.flatnonzero(a >= 0)
        inv[a[r]] = r
        maps[q] = inv
    return maps
