"""Permutation synchronization: ``synchronize_permutations`` and its methods.

Conventions
-----------
``pairwise[(i, j)]`` is an assignment ``a`` with ``a[u] = v`` (node ``u`` of object ``i`` matched to
node ``v`` of object ``j``, ``-1`` unmatched), i.e. the 0/1 matrix ``P_ij[u, v] = 1``. The absolute
map of object ``i`` is ``X_i`` (``n_i x d``, ``X_i[u, labels[i][u]] = 1``) and consistency means
``P_ij = X_i X_j^T``. The block matrix ``T`` has blocks ``w_ij P_ij`` (and ``w_ij P_ij^T`` below the
diagonal) and identity blocks on the diagonal; for consistent input ``T = X X^T``.
"""

from __future__ import annotations

import time
import warnings

import numpy as np
import scipy.linalg as sla
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components

from .._validation import (MAX_ITER, as_generator, check_bool, check_choice, check_int,
                           check_positive, check_real)
from ..exceptions import ConvergenceWarning, DegenerateInputError
from ..permutations import MultiMatching, cycle_inconsistency_arrays, solve_lap
from . import _spectral as spec
from ._linalg import RowBlockProduct, SlicedRowProducts, polar
from ._pairwise_input import StackedPairs, check_universe, parse_pairwise
from ._result import BlockRounding, PermutationSyncResult

__all__ = ["synchronize_permutations"]

_METHODS = ("spectral", "orthogonal", "matcheig")
#: eigenvalues below this fraction of the largest count as zero: their eigenvectors (an
#: arbitrary basis of a null space) are not used as universe directions
NULL_EIGENVALUE = 1e-6
#: an eigengap this fraction of the largest eigenvalue or more is a candidate cut for a given
#: universe above the slots the input needs (exact input: 1 against about 0.5)
_CLEAR_GAP = 1e-3
#: leading eigenvalues within this fraction of the largest form its cluster: 1 for every
#: universe node on exactly consistent input, one more for every part of a universe node that
#: no observed pair links to the rest. Dense eigenvalues are exact to about 1e-13; matrix-free
#: Ritz values were within 2e-7 of 1 here, and a tolerance of 1e-6 still missed one cluster in
#: 90 exact collections. A pair of relative weight w linking two parts moves an eigenvalue by
#: about w / 3: below the tolerance, such a pair counts as no link.
_CLUSTER = {"dense": 1e-9, "matrix_free": 1e-5}
_SOLVERS = ("auto", "dense", "matrix_free")


# --------------------------------------------------------------------------------------------
# helpers on stacked observations
# --------------------------------------------------------------------------------------------

def _subset(stk: StackedPairs, objs: np.ndarray) -> StackedPairs:
    """Observations among ``objs`` (sorted), objects renumbered 0..len(objs)-1."""
    local = np.full(stk.n_objects, -1, dtype=np.int64)
    local[objs] = np.arange(objs.size)
    keep = (local[stk.pairs[:, 0]] >= 0) & (local[stk.pairs[:, 1]] >= 0)
    sizes = stk.sizes[objs]
    n_max = int(sizes.max())
    return StackedPairs(
        n_objects=int(objs.size), sizes=sizes, pairs=local[stk.pairs[keep]],
        maps=None if stk.maps is None else stk.maps[keep][:, :n_max],
        soft=None if stk.soft is None else stk.soft[keep][:, :n_max, :n_max],
        weights=stk.weights[keep])


def _padded(labels, n_max):
    out = np.full((len(labels), n_max), -1, dtype=np.int64)
    for g, lab in enumerate(labels):
        out[g, : lab.size] = lab
    return out


def _agreement(stk: StackedPairs, labels, d: int):
    """(weighted agreements, observed matched entries, agreed entries) of labels vs input."""
    matching = labels if isinstance(labels, MultiMatching) else MultiMatching(labels, d)
    agree = 0.0
    n_obs = 0
    n_ok = 0
    for s in range(0, stk.pairs.shape[0], 50_000):
        pr = stk.pairs[s:s + 50_000]
        mp = stk.maps[s:s + 50_000]
        derived = matching.pairwise_array(pr)
        hit = (mp >= 0) & (derived == mp)
        agree += float((hit.sum(1) * stk.weights[s:s + 50_000]).sum())
        n_obs += int((mp >= 0).sum())
        n_ok += int(hit.sum())
    return agree, n_obs, n_ok


def _observed_and_output(stk: StackedPairs, labels, d: int, dobs=None):
    """Per object ``g``: ``(obs, out, w)``, its observed maps to its neighbours ``(deg, n_g)``,
    the output's maps on the same pairs and the pairs' weights ``(deg, 1)``."""
    ptr, dst, dmaps, dw = dobs if dobs is not None else spec.directed(stk)
    matching = MultiMatching(labels, d)
    for g in range(stk.n_objects):
        lo, hi = ptr[g], ptr[g + 1]
        n_g = int(stk.sizes[g])
        pairs = np.column_stack([np.full(hi - lo, g), dst[lo:hi]])
        yield dmaps[lo:hi, :n_g], matching.pairwise_array(pairs)[:, :n_g], dw[lo:hi, None]


def _support(obs, out, w) -> np.ndarray:
    """Weighted Jaccard agreement of the output maps ``out`` with ``obs``, per node."""
    agree = (w * ((obs >= 0) & (out == obs))).sum(0)
    claim = (w * ((obs >= 0) | (out >= 0))).sum(0)
    return np.where(claim > 0, agree / np.where(claim > 0, claim, 1.0), 0.0)


def _node_scores(stk: StackedPairs, labels, d: int, dobs=None):
    """Per-node support of the output: weighted Jaccard agreement with the observations.

    For node ``u`` of object ``g`` and every observed pair ``(g, j)``: the observation claims a
    partner when ``P_gj[u]`` is a node, the output claims one when ``j`` has a node in ``u``'s
    slot; the score is (weight of pairs where both claim the same partner) / (weight of pairs
    where at least one claims a partner), 0 when nothing is claimed.
    """
    return [_support(obs, out, w) for obs, out, w in _observed_and_output(stk, labels, d, dobs)]


def _observed_matches(stk: StackedPairs):
    """``(pairs, maps, ok, src, dst)`` of the observed pairs of positive weight: ``ok`` marks
    the entries that match, ``src`` / ``dst`` are each entry's flat node indices in the first
    / second object (``offsets[i] + u``, ``offsets[j] + maps[q, u]``; valid where ``ok``)."""
    pos = stk.weights > 0
    pairs, maps = stk.pairs[pos], stk.maps[pos]
    off = stk.offsets
    src = off[pairs[:, 0]][:, None] + np.arange(maps.shape[1])
    return pairs, maps, maps >= 0, src, off[pairs[:, 1]][:, None] + maps


def _raise_estimate(info, d_old: int, d_new: int, why: str) -> None:
    """Record that an estimated universe grew from ``d_old`` to ``d_new``, and why."""
    info["n_universe_rule"] = f"{info['n_universe_rule']}; raised from {d_old} to {d_new}: {why}"
    info["n_universe_estimate"] = d_new


def _separate_unlinked(stk: StackedPairs, labels, d: int, grow: bool):
    """Move the groups of a slot that the input keeps apart into slots of their own.

    The nodes in one slot form groups: the connected components of the observed matches among
    them. Nodes of two groups have no observed match with each other, so their placement adds
    nothing to the objective; when an observed pair compares them (one object holds a node of
    each, or a pair ``(i, j)`` has one group's node in ``i`` and the other's in ``j``) it adds
    a match that the input does not make. A slot's largest group stays; every other group that
    such a pair compares with the rest of the slot moves, largest first, to an empty slot, else
    to a used slot with which no observed pair compares it. When some group finds neither, all
    groups (as they were) are packed at once by :func:`~._spectral.pack_slots` if its faithful
    colouring fits in ``d``; else, with ``grow`` (an estimated universe), the groups left take
    new slots; without, they stay. The objective is unchanged, and exactly consistent partial
    input comes back as given, where orthogonal synchronization (whose objective ties such
    matches with none) returned spurious matches on 21 to 40 of 90 exact collections. Returns
    ``(labels, d, number of groups that left their slot)``.
    """
    sizes = stk.sizes
    off = stk.offsets
    N = stk.n_objects
    lab = np.concatenate([np.asarray(x, dtype=np.int64) for x in labels])
    pairs, _, ok, src, dst = _observed_matches(stk)
    src, dst = src[ok], dst[ok]
    same = (lab[src] == lab[dst]) & (lab[src] >= 0)
    M = int(off[-1])
    links = sp.coo_matrix((np.ones(int(same.sum())), (src[same], dst[same])), shape=(M, M))
    group = connected_components(links, directed=False)[1]
    owner = np.repeat(np.arange(N), sizes)
    placed = np.flatnonzero(lab >= 0)
    key, part, count = np.unique(np.column_stack([lab[placed], group[placed]]), axis=0,
                                 return_inverse=True, return_counts=True)
    if len(key) == np.unique(key[:, 0]).size:         # one group per slot: nothing to move
        return labels, d, 0
    seen = spec.compared_objects(pairs, N)
    holds = np.zeros((N, max(d, 1)), dtype=bool)
    holds[owner[placed], lab[placed]] = True
    order = np.lexsort((-count, key[:, 0]))          # per slot, largest group first
    key, count = key[order], count[order]
    first = np.r_[True, key[1:, 0] != key[:-1, 0]]
    loose = np.flatnonzero(~first)
    loose = loose[np.argsort(-count[loose], kind="stable")]
    moved = 0
    stuck = []                                          # groups with no room one at a time

    def compared_with(nodes):
        objs = np.zeros(N)
        objs[owner[nodes]] = 1.0
        return (seen @ objs) > 0

    for q in loose:
        slot, g = int(key[q, 0]), int(key[q, 1])
        nodes = placed[(lab[placed] == slot) & (group[placed] == g)]
        compared = compared_with(nodes)
        holds[owner[nodes], slot] = False
        if not holds[compared, slot].any():            # nothing in the slot compares it
            holds[owner[nodes], slot] = True
            continue
        free = np.flatnonzero(~holds.any(0)[:d])
        fits = free if free.size else np.flatnonzero(~holds[compared].any(0)[:d])
        if not fits.size:
            holds[owner[nodes], slot] = True
            stuck.append(nodes)
            continue
        lab[nodes] = int(fits[0])
        holds[owner[nodes], int(fits[0])] = True
        moved += 1
    if stuck:
        # no room one group at a time: pack all groups at once (a greedy colouring in which
        # compared groups differ) when that fits in d; else, for an estimated universe, the
        # groups left take new slots (each the first new one that no observed pair compares
        # it with)
        parts = np.full(M, -1, dtype=np.int64)
        parts[placed] = part.ravel()                    # each group as it was: its own slot
        packed, _ = spec.pack_slots([parts[off[g]:off[g + 1]] for g in range(N)], pairs, d,
                                    faithful_only=True)
        if packed is not None:
            return packed, d, moved + len(stuck)
        if grow:
            d0 = d
            for nodes in stuck:
                compared = compared_with(nodes)
                fits = np.flatnonzero(~holds[compared].any(0)[d0:d]) + d0
                if fits.size:
                    target = int(fits[0])
                else:
                    target = d
                    d += 1
                    holds = np.hstack([holds, np.zeros((N, 1), dtype=bool)])
                holds[owner[nodes], lab[nodes[0]]] = False
                lab[nodes] = target
                holds[owner[nodes], target] = True
                moved += 1
    if not moved:
        return labels, d, 0
    return [lab[off[g]:off[g + 1]] for g in range(N)], d, moved


def _refine_labels(stk: StackedPairs, labels, d: int, max_sweeps: int, dobs=None,
                   start: float | None = None):
    """Projected power method on the discrete objective (Chen & Candes 2016, block form).

    Gauss-Seidel sweeps ``X_g <- LMO(sum_j w_gj P_gj X_j)``: the objective is linear in ``X_g``
    with the other objects fixed, so the rectangular Hungarian (every node placed, at most one
    node per slot) is the exact block maximizer and the objective never decreases. A bonus far
    below any weight keeps the current slot on ties (no drifting between equal optima). Stops
    after a sweep that changes nothing, or after ``max_sweeps``. Returns
    ``(labels, objective history, sweeps)``; ``start``: the objective of ``labels`` when the
    caller has it. The history after the start is kept by the block updates' gains (the
    objective's terms of the pairs at ``g``, which are the only ones an update of ``X_g``
    changes), not recomputed over all pairs each sweep (18 of ENZYMES' 41 refinement seconds).
    """
    sizes = stk.sizes
    N = stk.n_objects
    n_max = int(sizes.max())
    ptr, dst, dmaps, dw = dobs if dobs is not None else spec.directed(stk)
    lab = _padded(labels, n_max + 1)                      # column n_max stays -1
    pos = dw[dw > 0]
    tie = 1e-9 * (float(pos.min()) if pos.size else 1.0)
    if start is None:
        start = _agreement(stk, [lab[g, : sizes[g]] for g in range(N)], d)[0]
    history = [float(start)]
    sweeps = 0
    for sweeps in range(1, max_sweeps + 1):
        changed = 0
        gain = 0.0
        for g in range(N):
            lo, hi = ptr[g], ptr[g + 1]
            n_g = int(sizes[g])
            if lo == hi:
                continue
            a = dmaps[lo:hi, :n_g]
            tgt = lab[dst[lo:hi, None], np.where(a >= 0, a, n_max)]      # (deg, n_g) slots
            # S[u, slot] = weight of the pairs that put u's partner in slot; no partner: bin
            # d of row u, dropped (entries are summed in the same order as when they were
            # selected first, 7 s faster on ENZYMES)
            key = np.where(tgt >= 0, tgt, d)
            key += np.arange(n_g) * (d + 1)
            S = np.bincount(key.ravel(), weights=np.broadcast_to(dw[lo:hi, None], key.shape)
                            .ravel(), minlength=n_g * (d + 1)).reshape(n_g, d + 1)[:, :d]
            S = np.ascontiguousarray(S, dtype=float)
            cur = lab[g, :n_g]
            placed = np.flatnonzero(cur >= 0)
            before = S[placed, cur[placed]]
            S[placed, cur[placed]] += tie
            new = solve_lap(S)
            if not np.array_equal(new, cur):
                S[placed, cur[placed]] = before
                put = np.flatnonzero(new >= 0)
                gain += float(S[put, new[put]].sum() - before.sum())
                lab[g, :n_g] = new
                changed += 1
        history.append(history[-1] + gain)
        if changed == 0:
            break
    return [lab[g, : sizes[g]].copy() for g in range(N)], history, sweeps


# --------------------------------------------------------------------------------------------
# one connected component
# --------------------------------------------------------------------------------------------

def _consistent_parts(stk: StackedPairs) -> int | None:
    """The number of connected components of the graph that the observed matches (pairs of
    positive weight) draw on the nodes when the input is exactly representable, else None.

    Exactly representable: no component holds two nodes of one object, and no node that an
    observed pair leaves unmatched (in either direction) shares a component with a node of the
    other object. Each component is then a part of a universe node, and the eigenvalue-1
    cluster, one copy per component, holds the parts to round. Other input keeps the leading
    ``d`` eigenvectors: noisy maps on sparse view graphs have hundreds of components, whose
    cluster cost the eigensolver 8x and scrambled the rounding (500 objects of 30 nodes, 1 %
    of the pairs observed, 20 % corrupted, ``d`` given: 13 s -> 106 s, accuracy 0.23 -> 0.06).
    """
    if stk.maps is None:
        return None
    off, sizes, N = stk.offsets, stk.sizes, stk.n_objects
    pairs, maps, ok, src, dst = _observed_matches(stk)
    cols = np.arange(maps.shape[1])
    M = int(off[-1])
    links = sp.coo_matrix((np.ones(int(ok.sum())), (src[ok], dst[ok])), shape=(M, M))
    n_comp, comp = connected_components(links, directed=False)
    comp = comp.astype(np.int64)
    key = comp * N + np.repeat(np.arange(N, dtype=np.int64), sizes)
    if np.unique(key).size != key.size:
        return None
    # unmatched by the pair: the nodes of i mapped to -1, the nodes of j that no node hits
    hit = np.zeros(maps.shape, dtype=bool)
    rows = np.broadcast_to(np.arange(len(maps))[:, None], maps.shape)
    hit[rows[ok], maps[ok]] = True
    alone_i = (cols < sizes[pairs[:, 0]][:, None]) & ~ok
    alone_j = (cols < sizes[pairs[:, 1]][:, None]) & ~hit
    other_i = np.broadcast_to(pairs[:, 1][:, None], maps.shape)
    other_j = np.broadcast_to(pairs[:, 0][:, None], maps.shape)
    src_j = off[pairs[:, 1]][:, None] + cols
    claimed = np.concatenate([comp[src[alone_i]] * N + other_i[alone_i],
                              comp[src_j[alone_j]] * N + other_j[alone_j]])
    return None if np.isin(claimed, key).any() else int(n_comp)


class _LeadingEigs:
    """Leading eigenpairs of the synchronization matrix ``A`` (a stage helper of
    :func:`_spectral_embedding`): dense ``eigh`` or the matrix-free block solver, which runs
    its products in ``A``'s float32 on row blocks (threads, bit-identical) and its Ritz steps
    in float64. Counts the products (one per dense solve) and keeps whether the last solve
    converged."""

    def __init__(self, A, use: str, tol: float, rng):
        self.A, self.use, self.tol, self.rng = A, use, tol, rng
        self.M = A.shape[0]
        self.dense = A.toarray() if use == "dense" else None
        self.op = None if use == "dense" else RowBlockProduct(A)
        self.n_prod, self.converged = 0, True

    def matmat(self, X):
        return (self.op @ X.astype(self.A.dtype)).astype(np.float64)

    def __call__(self, k_vals: int, k_vec: int, V0=None):
        """``(values, vectors)``: the ``k_vals`` largest eigenvalues, descending, and the
        eigenvectors of the ``k_vec`` largest; ``V0`` starts the matrix-free solver."""
        if self.dense is not None:
            w, U = sla.eigh(self.dense, subset_by_index=[self.M - max(k_vals, k_vec),
                                                         self.M - 1])
            self.n_prod += 1
            return w[::-1], U[:, ::-1]
        vals, U, n_p, _, self.converged = spec.synchronization_eigs(
            self.matmat, self.M, k_vec, k_values=k_vals, tol=self.tol, V0=V0, rng=self.rng)
        self.n_prod += n_p
        return vals, U

    def cluster_size(self, vals) -> int:
        """How many leading eigenvalues equal the largest, up to the solver's accuracy."""
        return int(np.count_nonzero(vals >= (1.0 - _CLUSTER[self.use]) * vals[0]))


def _spectral_embedding(stk, d, solver, tol, rng, info, cluster=False):
    """Top eigenvectors of the normalized block matrix (and the universe size if ``d`` is None).

    ``cluster``: partial maps only, and only when no component of the nodes' match graph holds
    two nodes of one object (:func:`_consistent_parts`). When more than ``d`` leading
    eigenvalues equal the largest (exactly consistent input on an incomplete view graph: a
    universe node whose holders no observed pair links splits into parts, each with
    eigenvalue 1), the eigenvectors of the whole cluster are returned (more than ``d``
    columns): the first ``d`` of them would be an arbitrary cut of one eigenspace, whose
    rounding contradicted exact input.

    Stages: build the operator; solve for the leading eigenpairs that ``d`` asks for;
    estimate ``d`` when it is None (:func:`_estimate_universe_size`); widen to the whole
    eigenvalue-1 cluster (:func:`_widen_to_cluster`); choose the columns to round
    (:func:`_embedding_columns`).
    """
    M = int(stk.sizes.sum())
    n_max = int(stk.sizes.max())
    use = solver
    if solver == "auto":
        use = "dense" if M <= spec.DENSE_MAX else "matrix_free"
    t0 = time.perf_counter()
    dobs = spec.directed(stk)
    # matrix-free products run in float32 (half the memory traffic); Ritz steps in float64
    A = spec.block_matrix(stk, directed_obs=dobs,
                          dtype=np.float64 if use == "dense" else np.float32)
    info["seconds_build"] = time.perf_counter() - t0
    info["operator_nnz"] = int(A.nnz)
    info["solver"] = use
    t0 = time.perf_counter()
    if d is None and stk.is_full:
        d = n_max
        info["n_universe_rule"] = "full permutations: d = number of nodes"
    given = d is not None and "n_universe_rule" not in info
    k_vals = min(M, 2 * n_max + 10 if d is None else d)
    k_vec = min(d if d is not None else n_max, M)
    eigs = _LeadingEigs(A, use, tol, rng)
    V0 = None if use == "dense" else spec.reference_start(
        stk, spec.krylov_block(max(k_vals, k_vec), M), dobs, rng)
    vals, U = eigs(k_vals, k_vec, V0)
    if d is None:
        d, vals, U, k_vals = _estimate_universe_size(eigs, vals, U, k_vals, k_vec, n_max, info)
    n_top = 0
    n_comp = (_consistent_parts(stk) if cluster and not stk.is_full and vals.size
              and vals[0] > 0 else None)
    if n_comp is not None:
        vals, U, n_top, k_vals = _widen_to_cluster(eigs, vals, U, d, k_vals, n_comp)
    info["eigenvalues"] = np.asarray(vals[: max(k_vals, 1)])
    info["seconds_eigen"] = time.perf_counter() - t0
    k = _embedding_columns(stk, U, vals, d, n_top, given, info)
    return U[:, :k], d, eigs.n_prod, eigs.converged, A


def _estimate_universe_size(eigs: _LeadingEigs, vals, U, k_vals: int, k_vec: int, n_max: int,
                            info):
    """``(d, vals, U, k_vals)``: the universe size from the eigengap rule, the spectrum widened
    until the rule can trust its gap, and at least ``d`` eigenvectors."""
    M = eigs.M
    # Eigengap rule on the leading k_vals eigenvalues (k_vals = 2 n_max + 10 at first). If the
    # largest gap is the last one computed, or the smallest computed eigenvalue is still above
    # half the largest (we have not left the cluster of the d leading eigenvalues, which are
    # all 1 for consistent input), the gap may lie further down: double k_vals (up to M) and
    # look again.
    while True:
        d, rule = spec.estimate_universe(vals, n_max)
        at_end = d >= vals.size - 1
        still_high = vals[-1] > 0.5 * vals[0]
        if not (at_end or still_high) or k_vals >= M:
            break
        k_vals = min(M, 2 * k_vals)
        vals, U = eigs(k_vals, k_vec, U)
    if vals.size >= M and vals[-1] > 0.5 * vals[0]:
        # the whole spectrum computed and no drop anywhere: every node is its own cluster (the
        # maps observe no correspondence); the gap rule alone fell back to n_max and matched
        # nodes that the input leaves unmatched
        d = M
        rule = ("no eigengap: the whole spectrum stays above half its largest value (no "
                "node corresponds to another): every node its own slot, d = total nodes")
    info["n_universe_rule"] = rule
    info["n_universe_estimate"] = d
    info["n_universe_candidates"] = (n_max, int(vals.size - 1))
    if d == vals.size - 1 and vals.size < M:
        info["n_universe_warning"] = "estimate at the end of the computed spectrum"
    if d > U.shape[1]:
        _, U = eigs(min(d, M), min(d, M), U)
    return d, vals, U, k_vals


def _widen_to_cluster(eigs: _LeadingEigs, vals, U, d: int, k_vals: int, n_comp: int):
    """``(vals, U, n_top, k_vals)`` with the eigenvectors of the whole eigenvalue-1 cluster
    (``n_top`` leading eigenvalues equal to the largest) of exactly representable input, whose
    match graph has ``n_comp`` connected components."""
    n_top = eigs.cluster_size(vals)
    if n_top >= vals.size and vals.size < eigs.M:
        # every computed eigenvalue is in the cluster: eigenvalue 1 has one copy per connected
        # component of the graph the observed matches draw on the nodes, so the cluster can go
        # on only when there are more components (exact input: one per part of a universe
        # node)
        if n_comp > vals.size:
            k_vals = min(eigs.M, n_comp + 1)
            vals, U = eigs(k_vals, k_vals, U)
            n_top = eigs.cluster_size(vals)
    if d < n_top and U.shape[1] < n_top:
        vals, U = eigs(vals.size, n_top, U)
    return vals, U, n_top, k_vals


def _embedding_columns(stk, U, vals, d: int, n_top: int, given: bool, info) -> int:
    """How many leading columns of ``U`` to round: ``d`` less the null-space eigenvectors, or
    fewer where the eigengap or the cluster agrees strictly more with the input, or the whole
    eigenvalue-1 cluster (``n_top``) when it is wider than ``d``."""
    M, n_max = int(stk.sizes.sum()), int(stk.sizes.max())
    k = min(d, M, U.shape[1])
    lead = np.asarray(vals[:k], dtype=float)
    if lead.size == k and k > 1 and lead[0] > 0:
        # a given d above the slots the input uses: the extra eigenvectors span a null space
        # (eigenvalue 0), an arbitrary basis whose entries are as large as the informative
        # ones; in the row-normalized embedding they scrambled exactly consistent input. They
        # are left out: their slots stay empty unless an object needs more of them
        k = max(int(np.count_nonzero(lead > NULL_EIGENVALUE * lead[0])), 1)
        if k < lead.size:
            info["null_eigenvectors_dropped"] = int(lead.size - k)
        if given and k > n_max:
            k = _given_universe_columns(stk, U, lead[:k], d, n_max, info)
    if n_top > d:
        info["eigenvalue_cluster"] = n_top
        k = min(n_top, U.shape[1])
    elif n_max <= n_top < k:
        k = _cluster_columns(stk, U, n_top, k, d, info)
    return k


def _cluster_columns(stk, U, n_top: int, k: int, d: int, info) -> int:
    """Round the eigenvalue cluster alone (``n_top`` columns) or all ``k``: the cluster only if
    it agrees strictly more with the input (on ties all ``k``, as before). Exactly consistent
    partial input whose universe is estimated or given above its cluster (an incomplete view
    graph adds eigenvalues below 1 but near it: 0.93 on a 40 % view graph) got those columns
    too, and their rounding contradicted the input."""
    best = _fewer_if_better(stk, U, n_top, k, d)
    info["cluster_columns"] = {"cluster": int(n_top), "all": int(k), "chosen": int(best)}
    return best


def _fewer_if_better(stk, U, fewer: int, k: int, d: int) -> int:
    """``fewer`` if rounding the first ``fewer`` columns of ``U`` into ``d`` slots agrees
    strictly more with the input than rounding all ``k``, else ``k`` (ties keep all: fewer
    columns can merge nodes that the input leaves unmatched, which agreement does not see)."""
    scores = {kk: _agreement(stk, spec.round_to_universe(U[:, :kk], stk.sizes, d), d)[0]
              for kk in (fewer, k)}
    return fewer if scores[fewer] > scores[k] + 1e-9 * max(abs(scores[k]), 1.0) else k


def _given_universe_columns(stk, U, lead, d: int, n_max: int, info) -> int:
    """How many leading eigenvectors to round when ``d`` was given above the slots the input
    needs. With unobserved pairs the extra eigenvalues are not 0 (0.53 on a 60 % view graph of
    exact maps): the null-space rule keeps them, and rounding them scrambled exact input. When
    the eigengap count (:func:`estimate_universe`) marks a clear gap, its rounding is tried too
    and kept if it agrees strictly more with the input (on ties all columns are kept: fewer
    slots can merge nodes that the input leaves unmatched, which agreement does not see)."""
    k_gap = spec.estimate_universe(lead, n_max)[0]
    k = lead.size
    if k_gap >= k or lead[k_gap - 1] - lead[k_gap] < _CLEAR_GAP * lead[0]:
        return k
    best = _fewer_if_better(stk, U, k_gap, k, d)
    info["eigengap_columns"] = {"eigengap": int(k_gap), "all": int(k), "chosen": int(best)}
    return best


def _packed_cluster(stk, V, d: int, estimated: bool, info):
    """``(labels, d)`` from an embedding wider than ``d`` (the eigenvalue-1 cluster), else
    ``(None, d)``.

    The whole cluster is rounded into one slot per part of a universe node, then the parts are
    packed into ``d`` slots where no observation compares them; an estimated universe grows to
    the slots that packing needs (exact input is then returned as given), a given one is
    honoured. ``(None, d)`` too when no packing fits.
    """
    if V.shape[1] <= d:
        return None, d
    labels, info["cluster_packing"] = spec.pack_slots(
        spec.round_to_universe(V, stk.sizes, V.shape[1]), stk.pairs[stk.weights > 0],
        V.shape[1] if estimated else d)
    if labels is not None:
        used = 1 + max((int(lab.max()) for lab in labels if lab.size), default=-1)
        if used > d:
            _raise_estimate(info, d, used, f"the eigenvalue-1 cluster has {V.shape[1]} parts, "
                            f"and {used} slots (a greedy colouring) keep apart every two that "
                            f"an observation compares")
            d = used
    return labels, d


def _component_spectral(stk, d, solver, tol, rng, info, refine=0):
    estimated = d is None or "n_universe_rule" in info
    V, d, n_prod, ok, _ = _spectral_embedding(stk, d, solver, tol, rng, info, cluster=True)
    t0 = time.perf_counter()
    labels, d = _packed_cluster(stk, V, d, estimated, info)
    if labels is None:
        labels = spec.round_to_universe(V[:, :d], stk.sizes, d)
    info["seconds_round"] = time.perf_counter() - t0
    if refine > 0:
        t0 = time.perf_counter()
        labels, hist, sweeps = _refine_labels(stk, labels, d, refine)
        info["discrete_objective_history"] = np.asarray(hist)
        info["refine_sweeps"] = sweeps
        info["seconds_refine"] = time.perf_counter() - t0
    return labels, d, n_prod, ok, V


def _component_orthogonal(stk, d, solver, tol, rng, info, max_iter, orth_tol, refine,
                          separate=True):
    estimated = d is None or "n_universe_rule" in info
    V, d, n_prod, ok_eig, _ = _spectral_embedding(stk, d, solver, tol, rng, info,
                                                  cluster=separate)
    # exactly representable input whose eigenvalue-1 cluster is wider than d: the spectral
    # method's packed cluster is the spectral candidate, the polar sweeps start from the
    # leading d columns (other input never gets the cluster, see _consistent_parts)
    packed, d = _packed_cluster(stk, V, d, estimated, info)
    V = V[:, :d]
    sizes = stk.sizes
    off = stk.offsets
    N = stk.n_objects
    k = V.shape[1]
    if k < d:
        V = np.hstack([V, np.zeros((V.shape[0], d - k))])
    dobs = spec.directed(stk)
    # Off-diagonal blocks w_gj P_gj of the (unnormalized) block matrix, in CSR: the rows of
    # object g are one contiguous slice, so B_g = sum_j w_gj P_gj Q_j is one sparse-dense
    # product (3x faster than gathering Q_j block by block, measured on MUTAG-size problems)
    T = spec.block_matrix(stk, normalize=False, directed_obs=dobs)
    T.setdiag(0.0)
    T.eliminate_zeros()
    # Q_g: n_g x d with orthonormal rows, stacked object after object
    Q = np.vstack([polar(V[off[g]:off[g + 1]] + 1e-12) for g in range(N)])

    # The objective sum_g <Q_g, B_g> (B_g = sum_j w_gj P_gj Q_j, each pair twice) is computed
    # once; a sweep then adds each update's change 2 <Q_g' - Q_g, B_g> (T is symmetric with
    # zero diagonal blocks, so B_g does not depend on Q_g): one full product fewer per sweep
    # (18 of ENZYMES' 46 polar-sweep seconds)
    history = [float(np.sum(Q * (RowBlockProduct(T) @ Q)))]
    converged = False
    it = 0
    with SlicedRowProducts(T, off) as rows:
        for it in range(1, max_iter + 1):
            gain = 0.0
            for g in range(N):
                B = rows(g, Q)
                if np.any(B):
                    new = polar(B)
                    gain += 2.0 * float(np.sum((new - Q[off[g]:off[g + 1]]) * B))
                    Q[off[g]:off[g + 1]] = new
            history.append(history[-1] + gain)
            if abs(history[-1] - history[-2]) <= orth_tol * max(abs(history[-1]), 1e-12):
                converged = True
                break
    if not converged:
        warnings.warn(f"orthogonal synchronization stopped after max_iter={max_iter} sweeps "
                      f"(relative change "
                      f"{abs(history[-1] - history[-2]) / max(abs(history[-1]), 1e-12):.2e} > tol)",
                      ConvergenceWarning, stacklevel=4)
    info["relaxed_objective_history"] = np.asarray(history)
    info["polar_sweeps"] = it
    stacked = Q
    # Round both the spectral start and the polar end point, refine each by the projected
    # power method on the discrete objective, keep the better one. All candidates are scored
    # by the same discrete objective that the method maximizes, so this is a safeguard against
    # the polar iteration ending in a worse local optimum, not a change of objective.
    cands = {"orthogonal": spec.round_to_universe(stacked, sizes, d),
             "spectral": packed if packed is not None else spec.round_to_universe(V[:, :k],
                                                                                sizes, d)}
    scores = {}
    best = None
    for name, lab in cands.items():
        before = _agreement(stk, lab, d)[0]
        sweeps = 0
        if refine > 0:
            lab, hist, sweeps = _refine_labels(stk, lab, d, refine, dobs, start=before)
            info[f"discrete_objective_history_{name}"] = np.asarray(hist)
        score = _agreement(stk, lab, d)[0]
        scores[name] = {"rounded": before, "refined": score, "refine_sweeps": sweeps}
        if best is None or score > best[1] + 1e-9 * max(abs(score), 1.0):
            best = (name, score, lab)
    info["candidates"] = scores
    info["chosen"] = best[0]
    labels = best[2]
    if separate and not stk.is_full:     # partial maps: '-1' entries tie with matches
        d_in = d
        labels, d, info["unlinked_groups_moved"] = _separate_unlinked(stk, labels, d, estimated)
        if d > d_in:
            _raise_estimate(info, d_in, d, "groups of nodes that no observed match links to "
                            "the rest of their slot, and that an observed pair compares with "
                            "it, took new slots")
    return labels, d, it, converged and ok_eig, stacked


# --------------------------------------------------------------------------------------------
# front door
# --------------------------------------------------------------------------------------------

def synchronize_permutations(pairwise, *, n_universe: int | None = None,
                             method: str = "spectral", mask=None, weights=None, sizes=None,
                             solver: str = "auto", disconnected: str = "separate",
                             max_iter: int = 100, tol: float = 1e-6,
                             eig_tol: float = 1e-4, threshold: float = 0.5,
                             refine: int | None = None, min_score: float | None = None,
                             max_triangles: int = 100_000, keep_embedding: bool = False,
                             rng=None) -> PermutationSyncResult:
    r"""Make pairwise (partial) permutations cycle-consistent through a universe of nodes.

    Finds absolute maps ``X_i`` (node of object ``i`` -> universe slot, ``n_i x d``, injective)
    that maximize the agreement with the observations,

    .. math:: \max_{X_i} \sum_{(i,j) \in \Omega} w_{ij} \langle P_{ij}, X_i X_j^\top \rangle ,

    and returns them as ``labels``; every derived map ``pairwise(i, j)`` is cycle-consistent.

    Methods:

    * ``"spectral"`` (Pachauri et al. 2013; partial permutations: the multi-simplex model of
      the methods page *Permutation synchronization*): the leading ``d`` eigenvectors of the
      degree-normalized block matrix
      ``D^{-1/2} T D^{-1/2}``, then rounding: a pivoted QR picks one prototype row per universe
      slot, a Procrustes rotation aligns them with the slots, every object is assigned by
      rectangular Hungarian (every node placed, at most one node per slot) and a few
      Procrustes/Hungarian refinements follow. Dense ``eigh`` when ``sum n_i <= 2000``, otherwise
      matrix-free (sparse block matrix built once from index arrays; restarted block Krylov
      with Rayleigh-Ritz), see ``solver``.
    * ``"orthogonal"`` (methods page *Permutation synchronization*, section "Orthogonal"):
      spectral start ``Q_i = polar(U_i)``,
      Gauss-Seidel sweeps ``Q_i <- polar(sum_j w_ij P_ij Q_j)`` (each the exact block maximizer,
      so the relaxed objective never decreases; its history is
      ``info["relaxed_objective_history"]``)
      until the relative change is below ``tol`` or ``max_iter`` sweeps. Both the polar end point
      and the spectral start are rounded, each is refined by the projected power method
      (Chen & Candes 2016; Gauss-Seidel ``X_i <- Hungarian(sum_j w_ij P_ij X_j)``, monotone in
      the discrete objective, at most ``refine`` sweeps, default ``max_iter``), and the one with
      the higher objective is returned (``info["candidates"]``, ``info["chosen"]``). Since every
      candidate is scored by the objective the method maximizes, this is a safeguard against a
      poor local optimum of the polar iteration, not a change of objective. On exactly
      representable partial input the spectral candidate is the spectral method's packed
      eigenvalue-1 cluster (below). With partial maps the nodes of each slot then form groups
      (the components of the observed matches among them); every group but the largest that
      an observed pair compares with another node of its slot moves to an empty slot, else to
      a used one that no observed pair compares it with; when some group finds neither, all
      groups are packed at once by a greedy colouring in which compared groups differ, if
      that fits in ``d``, else (estimated universe only) the groups left take new slots
      (``info["unlinked_groups_moved"]``). The objective is unchanged: '-1' entries carry no
      weight, so a match the input does not make tied with none, and exactly consistent
      partial input came back with such matches on 21-40 of 90 exact collections; all 90 now
      come back as given, with either solver.
    * ``"matcheig"`` (Maset, Arrigoni, Fusiello 2017), a fast baseline: the same eigenvectors,
      rows normalized, and each block ``U_i U_j^T`` rounded independently by Hungarian,
      dropping matches below ``threshold``. Its ``pairwise(i, j)`` need not be cycle-consistent
      (``cycle_consistent=False``); ``labels`` then holds the consistent rounding of the same
      eigenvectors, i.e. the ``"spectral"`` answer, so that one result type serves every method.

    Universe size: ``n_universe`` if given; otherwise ``n`` when all objects have ``n`` nodes and
    every observed map is a bijection; otherwise the eigengap of the degree-normalized spectrum:
    ``d = argmax_{n_max <= d < K} (l_d - l_{d+1})`` over the ``K`` leading eigenvalues computed,
    ``K = 2 n_max + 10`` at first, doubled (up to ``sum n_i``) while the largest gap is the
    last one or the ``K``-th eigenvalue is still above half the first (the cluster of leading
    eigenvalues, all 1 for consistent input, has not ended). ``info["n_universe_rule"]`` states
    the rule and range used, ``info["n_universe_candidates"]`` the range ``(n_max, K - 1)``,
    ``info["n_universe_estimate"]`` the result and ``info["eigenvalues"]`` the spectrum. When
    some pairs of objects are unobserved (an incomplete view graph) the eigengap overestimates
    (a universe node's eigenvalues are those of the view graph's normalized adjacency, spread
    up to 1); there the orthogonal method runs in the eigengap's universe, whose
    projected-power sweeps gather the slots the spectrum splits, and the slots it uses are the
    estimate (``info["n_universe_eigengap"]`` keeps the eigengap's value). Measured with
    RRWM matches of 16 graphs (d = 20, each matched to 6 others, deformation 0.05,
    ``benchmarks/universe_estimate.py --graphs 16 --degree 6``): right on 17 of 20
    collections, 0.15 slots too many on average, against 5 of 20 and 28 slots too many.

    Exactly consistent partial maps on an incomplete view graph can have more eigenvalues
    equal to the largest than the universe has slots: a universe node whose holders no
    observed pair links is one part per group, each with eigenvalue 1. The spectral methods
    then round that whole cluster (``info["eigenvalue_cluster"]``), one slot per part, and
    pack the parts into ``d`` slots by a greedy colouring in which two parts conflict when one
    object holds both or an observed pair compares them (``info["cluster_packing"]``:
    ``"faithful"``, or ``"holders"`` when a given ``d`` is too small for that and only the
    first rule is kept). An estimated ``d`` grows to what the faithful packing needs; exact
    input then comes back as given. (Eigenvalue 1 has one copy per connected component of the
    graph that the observed matches draw on the nodes. These rules apply only to exactly
    representable input: no component holds two nodes of one object, and no node that an
    observed pair leaves unmatched shares a component with a node of the other object. Other
    input keeps the leading ``d`` eigenvectors: on sparse view graphs its hundreds of
    components made the eigensolver 8x slower and the rounding worse.)

    With ``min_score``, nodes whose placement is weakly supported are left unplaced (label
    ``-1``): a node's score is the weighted fraction of its observed pairs in which the
    observation and the output name the same partner, among those where either names one
    (``info["node_scores"]``); nodes scoring below ``min_score`` are dropped.

    A disconnected observation graph is detected; with ``disconnected="separate"`` (default)
    every connected component is synchronized on its own, into its own universe (of size
    ``n_universe``, or its number of nodes when that is smaller), and the ids are
    offset so that different components never share a slot (``info["components"]``); maps
    between components are empty (all ``-1``). A given ``n_universe`` is the size of the
    result: when the components at that size need more slots in all, each is synchronized at
    its own estimated size and the slots left over stay empty; when those too are more than
    ``n_universe`` in all, a ``ValueError`` says so. With
    ``"raise"`` a :class:`~transync.exceptions.DegenerateInputError` names the components.

    Parameters
    ----------
    pairwise : dict {(i, j): assignment or 0/1 matrix}, iterable of (i, j, map) or array
        Observations; ``(j, i)`` may be omitted (it is the inverse). When both ``(i, j)`` and
        ``(j, i)`` are given they count as two observations of the pair, averaged in ``T``.
        An ``(N, N, n)`` assignment or ``(N, N, n, n)`` block array is read where ``mask``.
    n_universe : int, optional
        Universe size ``d``: at least the largest object, at most the total number of nodes.
        A ``d`` above the slots the input uses leaves the extra slots empty (their eigenvectors,
        of eigenvalue 0, are not used; ``info["null_eigenvectors_dropped"]`` counts them). With
        unobserved pairs the extra eigenvalues are not 0; the leading eigenvectors up to the
        eigengap are then rounded too, and the rounding that agrees more with the input is
        kept (``info["eigengap_columns"]``).
    method : {"spectral", "orthogonal", "matcheig"}, default="spectral"
    mask : (N, N) bool array, optional
        Which pairs to use.
    weights : (N, N) array or dict {(i, j): w}, optional
        Non-negative confidence of each pair (default 1): ``weights[i, j]`` (or the dict's
        ``(i, j)`` entry, else its ``(j, i)`` one) for the observation given as ``(i, j)``.
        Only their ratios matter: multiplying every weight by one constant changes nothing
        (the identity blocks of the block matrix carry the smallest positive weight). A
        weight of 0 leaves the pair out; at least one must be positive.
    sizes : (N,) int array, optional
        Object sizes when they cannot be read from the maps (default: assignment lengths,
        matrix shapes and the largest target).
    solver : {"auto", "dense", "matrix_free"}, default="auto"
        Eigensolver; ``info["solver"]`` records the one used.
    disconnected : {"separate", "raise"}, default="separate"
    max_iter, tol : int, float
        Polar sweeps and relative tolerance of ``"orthogonal"``.
    eig_tol : float, default=1e-4
        Relative residual tolerance of the matrix-free eigensolver.
    threshold : float in [0, 1], default=0.5
        ``"matcheig"`` drops block entries (cosines of the row-normalized embeddings) below it.
    refine : int, optional
        Maximum projected-power sweeps on the discrete objective after rounding. Default: 0 for
        ``"spectral"`` (plain Pachauri et al.) and ``max_iter`` for ``"orthogonal"``; only 0
        (or None) for ``"matcheig"``.
    min_score : float in [0, 1], optional
        Leave nodes whose support is below it unplaced (``-1``); default: every node placed.
    max_triangles : int, default=100000
        Triangles sampled for the input-consistency report ``info["input_consistency"]``.
    keep_embedding : bool, default=False
        Also return the relaxed (real-valued) solution before rounding as
        ``info["embedding"]``, a ``(sum n_i, d)`` float array whose rows ``offsets[g] ..
        offsets[g + 1]`` (``offsets = [0, *cumsum(sizes)]``) hold object ``g``'s ``Q_g``: the
        polar end point for ``"orthogonal"`` (orthonormal rows), the leading eigenvectors of
        the normalized block matrix for ``"spectral"`` and ``"matcheig"``. Components of a
        disconnected observation graph fill their own columns (their universe block); an object
        alone in its component gets its one-hot labels. Off by default to keep results small.
    rng : None, int or numpy.random.Generator
        Start block of the matrix-free eigensolver and triangle sampling.

    Returns
    -------
    PermutationSyncResult
        The consistent multi-matching (universe labels), its objective and the method's
        diagnostics in ``info``.

    Raises
    ------
    ValueError
        Non-permutation blocks, non-injective maps, mismatched sizes, ``i == j`` pairs, a
        universe smaller than the largest object, bad options.

    Examples
    --------
    >>> from transync.datasets import make_permutation_collection
    >>> from transync.synchronization import synchronize_permutations
    >>> data = make_permutation_collection(8, 6, corruption=0.25, rng=0)  # 7 of 28 pairs wrong
    >>> res = synchronize_permutations(data.pairwise)
    >>> data.accuracy(res.labels), res.n_universe, res.info["solver"]
    (1.0, 6, 'dense')
    >>> res.info["input_consistency"]["inconsistent_triangles"] > 0
    True
    >>> bool((res.pairwise(0, 3) == data.true_pairwise(0, 3)).all())
    True
    """
    opts = _check_options(method=method, solver=solver, disconnected=disconnected,
                          max_iter=max_iter, tol=tol, eig_tol=eig_tol, threshold=threshold,
                          refine=refine, min_score=min_score, max_triangles=max_triangles)
    check_bool(keep_embedding, "keep_embedding")
    gen = as_generator(rng)
    t_start = time.perf_counter()
    stk = parse_pairwise(pairwise, mask=mask, weights=weights, sizes=sizes)
    n_universe = check_universe(n_universe, stk.sizes)
    info: dict = {"method": method, "seconds_parse": time.perf_counter() - t_start}
    comps = _observation_components(stk, opts["disconnected"])
    info["components"] = comps
    labels, d_total, n_iter, converged, comp_info, embeddings = _synchronize_components(
        stk, comps, n_universe, opts, gen)
    if n_universe is not None and d_total > n_universe:
        # the components' universes are kept apart, each of up to n_universe slots: too many
        # in all (they were returned, e.g. 4 slots for n_universe=2, and nothing said so).
        # Each component at its own estimated size instead, the slots left over empty:
        labels, d_own, n_iter, converged, comp_info, embeddings = _synchronize_components(
            stk, comps, None, opts, gen)
        d_total = max(d_own, n_universe)
    if n_universe is not None and d_total > n_universe:
        groups = ", ".join("{" + ", ".join(map(str, c[:4].tolist())) + (", ..." if c.size > 4
                                                                          else "") + "}"
                           for c in comps[:3]) + (", ..." if len(comps) > 3 else "")
        raise ValueError(
            f"`n_universe`={n_universe} cannot hold the {len(comps)} groups of objects that no "
            f"observed pair links ({groups}): with disconnected='separate' each group gets its "
            f"own universe slots, {d_total} in all. Observe a pair between the groups, leave "
            "`n_universe` unset, or synchronize each group on its own")
    if not converged and method != "orthogonal":     # (orthogonal warns about its sweeps)
        # the matrix-free eigensolver stopped short: on a chain of 1001 3-node objects, exactly
        # consistent input came back with 12 of 1000 maps changed, and nothing said so
        warnings.warn(f"synchronize_permutations(method={method!r}): the matrix-free "
                      f"eigensolver did not reach eig_tol={opts['eig_tol']:g}; the result may "
                      "be poor (even exactly consistent input may not come back as given): "
                      f"pass solver='dense' ({int(stk.sizes.sum())} nodes in all) or a larger "
                      "eig_tol", ConvergenceWarning, stacklevel=2)
    dropped: tuple = ()
    if min_score is not None:
        scores = _node_scores(stk, labels, d_total)
        dropped = tuple(sc < opts["min_score"] for sc in scores)
        labels = [np.where(drop, -1, lab) for lab, drop in zip(labels, dropped)]
        info["node_scores"] = tuple(scores)
        info["n_unplaced"] = int(sum(int((lab < 0).sum()) for lab in labels))
    matching = MultiMatching(tuple(labels), d_total)
    if len(comps) == 1:
        for key, value in comp_info[0].items():
            if key not in ("objects", "offset"):
                info.setdefault(key, value)
    info["component_info"] = comp_info
    if keep_embedding:
        info["embedding"] = _stack_embeddings(stk, comps, comp_info, embeddings, d_total)
    agree, n_obs, n_ok = _agreement(stk, matching, d_total)
    info["input_disagreement"] = float(1 - n_ok / n_obs) if n_obs else 0.0
    info["input_consistency"] = cycle_inconsistency_arrays(
        stk.pairs, stk.maps, stk.sizes, max_triangles=opts["max_triangles"], rng=gen)
    objective = agree
    rounding = None
    if method == "matcheig":
        rounding = _block_rounding(stk, comps, embeddings, opts["threshold"], dropped)
        objective = _observed_objective(stk, rounding, info)
    info["seconds_total"] = time.perf_counter() - t_start
    return PermutationSyncResult(matching=matching, objective=float(objective),
                                 n_iter=int(n_iter), converged=bool(converged),
                                 cycle_consistent=rounding is None, info=info,
                                 _block_rounding=rounding)


def _check_options(*, method, solver, disconnected, max_iter, tol, eig_tol, threshold, refine,
                   min_score, max_triangles) -> dict:
    """Validate the options of :func:`synchronize_permutations` (stage 1)."""
    check_choice(method, "method", _METHODS)
    check_choice(solver, "solver", _SOLVERS)
    check_choice(disconnected, "disconnected", ("separate", "raise"))
    max_iter = check_int(max_iter, "max_iter", minimum=1, maximum=MAX_ITER)
    threshold = check_real(threshold, "threshold")
    if not 0.0 <= threshold <= 1.0:     # cosines of unit rows: above 1 nothing would match
        raise ValueError(f"`threshold` must lie in [0, 1] (the cosine below which MatchEIG drops "
                         f"a match), got {threshold!r}")
    if refine is None:
        n_refine = max_iter if method == "orthogonal" else 0
    else:
        n_refine = check_int(refine, "refine", minimum=0)
        if method == "matcheig" and n_refine:
            raise ValueError("`refine` does not apply to method='matcheig' (its pairwise maps are "
                             f"rounded block by block), got refine={refine!r}")
    if min_score is not None:
        min_score = check_positive(min_score, "min_score", allow_zero=True)
        if min_score > 1:
            raise ValueError(f"`min_score` must lie in [0, 1], got {min_score!r}")
    return {"method": method, "solver": solver, "disconnected": disconnected,
            "max_iter": max_iter, "tol": check_positive(tol, "tol"),
            "eig_tol": check_positive(eig_tol, "eig_tol"), "threshold": threshold,
            "refine": n_refine, "min_score": min_score,
            "max_triangles": check_int(max_triangles, "max_triangles", minimum=1)}


def _observation_components(stk: StackedPairs, disconnected: str) -> list[np.ndarray]:
    """Connected components of the observation graph (pairs with positive weight)."""
    pos = stk.weights > 0
    G = sp.coo_matrix((np.ones(int(pos.sum())), (stk.pairs[pos, 0], stk.pairs[pos, 1])),
                      shape=(stk.n_objects, stk.n_objects))
    n_comp, comp = connected_components(G, directed=False)
    order = np.argsort(comp, kind="stable")         # members of every component at once
    comps = np.split(order, np.flatnonzero(np.diff(comp[order])) + 1)
    if n_comp > 1 and disconnected == "raise":
        raise DegenerateInputError(
            f"the observation graph is disconnected: {n_comp} components, e.g. objects "
            f"{comps[0].tolist()[:10]} and {comps[1].tolist()[:10]}; pass "
            "disconnected='separate' to synchronize each component on its own")
    return comps


def _complete_view(pairs: np.ndarray, weights: np.ndarray, n_objects: int) -> bool:
    """Whether the ``(P, 2)`` observed ``pairs`` of positive ``weights`` join every two of the
    ``n_objects`` objects (in either direction)."""
    pos = np.asarray(pairs)[np.asarray(weights) > 0]
    pos = pos[pos[:, 0] != pos[:, 1]]
    n_pairs = np.unique(np.sort(pos, axis=1), axis=0).shape[0] if pos.size else 0
    return n_pairs == n_objects * (n_objects - 1) // 2


def _view_graph_universe(stk, opts, gen, info) -> int:
    """Universe size of objects of different sizes observed on an incomplete view graph.

    The eigengap rule assumes that the block matrix of consistent input has eigenvalues 1 (one
    per universe node) and 0. On an incomplete view graph a universe node's block is the
    normalized adjacency of the objects holding it, whose other eigenvalues spread over
    (-1, 1), and the largest gap lies far too low (numbers in :func:`synchronize_permutations`).
    The orthogonal synchronization started in that oversized universe merges the slots that the
    spectrum splits (its projected-power sweeps gather a universe node's nodes in one slot), so
    the slots it uses are the estimate.
    """
    tmp: dict = {}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ConvergenceWarning)
        lab, d0, *_ = _component_orthogonal(stk, None, opts["solver"], opts["eig_tol"], gen,
                                            tmp, opts["max_iter"], opts["tol"],
                                            opts["max_iter"], separate=False)
    used = np.unique(np.concatenate([np.asarray(x)[np.asarray(x) >= 0] for x in lab]))
    d = max(int(stk.sizes.max()), int(used.size))
    info["n_universe_rule"] = (
        f"incomplete view graph: slots used by the orthogonal synchronization in the eigengap "
        f"estimate's universe of {d0} ({tmp.get('n_universe_rule', 'eigengap')})")
    info["n_universe_estimate"] = d
    info["n_universe_eigengap"] = int(d0)
    info["eigenvalues"] = tmp.get("eigenvalues")
    return d


def _synchronize_components(stk, comps, n_universe, opts, gen):
    """Synchronize every component into its own block of universe slots (stage 3)."""
    labels: list = [None] * stk.n_objects
    offset = n_iter = 0
    converged = True
    comp_info, embeddings = [], []
    for objs in comps:
        cinfo: dict = {}
        # a component never needs more slots than it has nodes
        d_req = None if n_universe is None else min(n_universe, int(stk.sizes[objs].sum()))
        if objs.size == 1:
            g = int(objs[0])
            d_c = d_req if d_req is not None else int(stk.sizes[g])
            labels[g] = np.arange(stk.sizes[g], dtype=np.int64) + offset
            offset += d_c
            comp_info.append({"objects": objs, "n_universe": d_c})
            embeddings.append(None)
            continue
        sub = _subset(stk, objs)
        spectrum = None
        if (d_req is None and not sub.is_full
                and not _complete_view(sub.pairs, sub.weights, sub.n_objects)):
            d_req = _view_graph_universe(sub, opts, gen, cinfo)
            spectrum = cinfo["eigenvalues"]
        if opts["method"] == "orthogonal":
            lab, d_c, it, ok, emb = _component_orthogonal(
                sub, d_req, opts["solver"], opts["eig_tol"], gen, cinfo, opts["max_iter"],
                opts["tol"], opts["refine"])
        else:
            lab, d_c, it, ok, emb = _component_spectral(
                sub, d_req, opts["solver"], opts["eig_tol"], gen, cinfo, opts["refine"])
        for g, lab_g in zip(objs.tolist(), lab):
            labels[g] = np.where(lab_g >= 0, lab_g + offset, -1)
        cinfo.update({"objects": objs, "n_universe": d_c, "offset": offset})
        if spectrum is not None:                 # the spectrum of the estimate, not of d_c
            cinfo["eigenvalues"] = spectrum
        comp_info.append(cinfo)
        embeddings.append(emb)
        offset += d_c
        n_iter += it
        converged &= bool(ok)
    return labels, offset, n_iter, converged, comp_info, embeddings


def _stack_embeddings(stk, comps, comp_info, embeddings, d_total) -> np.ndarray:
    """The components' relaxed solutions as one ``(sum n_i, d_total)`` array (object order)."""
    off = stk.offsets
    out = np.zeros((int(off[-1]), d_total))
    col = 0
    for objs, cinfo, V in zip(comps, comp_info, embeddings):
        d_c = int(cinfo["n_universe"])
        if V is None:                                   # an object alone: its one-hot labels
            g = int(objs[0])
            out[off[g]:off[g + 1], col:col + int(stk.sizes[g])] = np.eye(int(stk.sizes[g]))
        else:
            rows = np.concatenate([np.arange(off[g], off[g + 1]) for g in objs.tolist()])
            k = min(V.shape[1], d_c)
            out[rows, col:col + k] = V[:, :k]
        col += d_c
    return out


def _block_rounding(stk, comps, embeddings, threshold, dropped=()) -> BlockRounding:
    """MatchEIG's block-wise rounding as plain (picklable) data; ``dropped``: per object, the
    nodes ``min_score`` left unplaced (they get no partner in the rounded maps either)."""
    component = np.zeros(stk.n_objects, dtype=np.int64)
    local = np.zeros(stk.n_objects, dtype=np.int64)
    normalized, offsets = [], []
    for c, (objs, V) in enumerate(zip(comps, embeddings)):
        component[objs] = c
        local[objs] = np.arange(objs.size)
        offsets.append(np.concatenate([[0], np.cumsum(stk.sizes[objs])]))
        normalized.append(None if V is None else
                          V / np.maximum(np.linalg.norm(V, axis=1, keepdims=True), 1e-300))
    return BlockRounding(embeddings=tuple(normalized), offsets=tuple(offsets),
                         component=component, local=local, sizes=stk.sizes.copy(),
                         threshold=float(threshold), dropped=tuple(dropped))


def _observed_objective(stk, rounding: BlockRounding, info: dict) -> float:
    """Weighted number of observed correspondences kept by block-wise rounded maps."""
    if stk.pairs.shape[0] > 50_000:
        info["objective_note"] = "not evaluated for matcheig above 50000 observed pairs"
        return float("nan")
    objective = 0.0
    for q in range(stk.pairs.shape[0]):
        i, j = stk.pairs[q]
        a = rounding(int(i), int(j))
        ob = stk.maps[q, : stk.sizes[i]]
        objective += stk.weights[q] * float(np.count_nonzero((ob >= 0) & (a == ob)))
    return objective
