"""Consistent refinement: coordinate ascent of the total affinity over consistent configurations.

A consistent multi-matching is a labelling ``L[g]`` of every graph's nodes into a universe; the
map ``i -> j`` is ``L_j^{-1} o L_i``. One sweep visits every graph ``g`` in turn, holds every
other graph's labels fixed, and moves ``L_g`` to the best of a few candidates by the sum of the
affinity scores of the pairs that touch ``g`` (Gauss-Seidel):

* **re-anchoring** on a neighbour ``k``: ``L_g <- L_k o m_gk`` makes the map ``g -> k`` equal to
  the pairwise stage's own proposal ``m_gk`` while every map among the other graphs stays as it
  is. This is CAO's composition idea (Yan et al. 2016) restricted to consistent configurations;
* **swaps** (2-opt): two nodes of ``g`` exchange their universe slots. All ``n(n - 1)/2`` swaps
  are ranked by their first-order gain ``d^T (K + K^T) x`` (``x`` the current maps of ``g``'s
  pairs, ``d`` the change of ``x`` a swap makes; one product per pair) and the best
  ``n_swaps`` of them are scored exactly.

Every candidate is scored exactly, a move is taken only when it raises the score, so the total
score never decreases and the output is consistent by construction; the sweeps stop when
nothing changes. The swaps fix what re-anchoring cannot: a graph whose proposals are all wrong
in the same few nodes (measured on N = 8 graphs of 10 nodes, deformation 0.15: mean accuracy
0.81 with re-anchoring only, 0.92 with swaps; see ``docs/multigraph.md``).
"""

from __future__ import annotations

import numpy as np

__all__ = ["refine_consistent"]

#: swaps scored exactly per graph and sweep (the best by first-order gain): on 12 problems of
#: N = 8 graphs, n = 10 nodes, deformation 0.15, the best 5 gave the accuracy of all 45
N_SWAPS = 10


def _inverse_rows(L: np.ndarray) -> np.ndarray:
    inv = np.empty_like(L)
    rows = np.arange(L.shape[0])[:, None]
    inv[rows, L] = np.arange(L.shape[1])[None, :]
    return inv


def _swap_gains(cur: np.ndarray, first: np.ndarray, grad: np.ndarray) -> np.ndarray:
    """(n, n) first-order gain of swapping the slots of nodes ``u`` and ``v`` of graph ``g``.

    ``cur`` (deg, n): current maps of ``g``'s pairs (``i -> j``); ``first``: pairs with ``g``
    first; ``grad`` (deg, n, n): ``(K + K^T) x`` of those pairs. ``M[u, v]`` is the gradient at
    node ``u`` of ``g`` taking ``v``'s current partner; a swap's gain is
    ``M[u, v] + M[v, u] - M[u, u] - M[v, v]``.
    """
    deg, n = cur.shape
    nodes = np.arange(n)
    M = np.zeros((n, n))
    if first.any():                 # g -> j: u takes v's partner cur[v]
        G, c = grad[first], cur[first]
        M += G[np.arange(len(G))[:, None, None], nodes[None, :, None], c[:, None, :]].sum(0)
    if (~first).any():              # i -> g: the node of i mapped to u is now mapped to v
        G, inv = grad[~first], _inverse_rows(cur[~first])
        M += G[np.arange(len(G))[:, None, None], inv[:, :, None], nodes[None, None, :]].sum(0)
    d = np.diag(M)
    return M + M.T - d[:, None] - d[None, :]


def refine_consistent(labels: np.ndarray, pairs: np.ndarray, proposals: np.ndarray, score, *,
                      gradient=None, n_swaps: int = N_SWAPS,
                      max_sweeps: int = 10) -> tuple[np.ndarray, list[float], dict]:
    """Re-anchor graphs on their neighbours and swap node slots while the total score increases.

    Parameters
    ----------
    labels : int ndarray of shape (N, n)
        Current consistent configuration: permutations of ``range(n)``.
    pairs : int ndarray of shape (P, 2)
        Observed pairs ``(i, j)``, ``i < j``.
    proposals : int ndarray of shape (P, n)
        Pairwise maps ``i -> j`` to re-anchor on (permutations).
    score : callable
        ``score(p_idx, assignments) -> (c,)``: affinity scores of maps
        ``pairs[p, 0] -> pairs[p, 1]``.
    gradient : callable, optional
        ``gradient(p_idx, X) -> (c, n, n)``: ``(K_p + K_p^T) vec(X_c)`` for 0/1 matrices ``X``
        (c, n, n) of pairs ``p_idx``. ``None``: no swaps (re-anchoring only).
    n_swaps : int, default=N_SWAPS
        Swaps scored exactly per graph and sweep (0: none).
    max_sweeps : int, default=10

    Returns
    -------
    labels : ndarray of shape (N, n)
    history : list of float
        Total score before the first sweep and after every sweep.
    moves : dict
        Moves taken: ``{"anchor": a, "swap": s}``.

    Examples
    --------
    >>> import numpy as np
    >>> pairs = np.array([[0, 1], [0, 2], [1, 2]])
    >>> truth = np.array([[0, 1, 2]] * 3)
    >>> def score(p, a):                      # the identity maps are the best ones
    ...     return (a == np.arange(3)).sum(1).astype(float)
    >>> start = np.array([[0, 1, 2], [1, 0, 2], [0, 1, 2]])
    >>> labels, hist, moves = refine_consistent(start, pairs, truth, score)
    >>> hist[0] < hist[-1] == 9.0, moves
    (True, {'anchor': 1, 'swap': 0})
    """
    L = np.array(labels, dtype=np.int64, copy=True)
    N, n = L.shape
    P = len(pairs)
    touching = [np.flatnonzero((pairs[:, 0] == g) | (pairs[:, 1] == g)) for g in range(N)]
    cols = np.arange(n)
    iu, ju = np.triu_indices(n, 1)
    n_swaps = min(int(n_swaps), len(iu)) if gradient is not None else 0

    def maps_of(p_idx, g, cand, Linv):
        """Maps of pairs ``p_idx`` (all touching ``g``) when ``g`` has labels ``cand`` (c, n)."""
        i, j = pairs[p_idx, 0], pairs[p_idx, 1]
        out = np.empty((cand.shape[0], len(p_idx), n), dtype=np.int64)
        first = i == g
        if first.any():                    # g -> j: node u -> Linv[j][cand[u]]
            out[:, first] = Linv[j[first][None, :, None], cand[:, None, :]]
        if (~first).any():                 # i -> g: node u of i -> candidate's node at L_i[u]
            cinv = _inverse_rows(cand)
            out[:, ~first] = cinv[np.arange(len(cand))[:, None, None], L[i[~first]][None, :, :]]
        return out

    def swaps_of(p_idx, g, Linv):
        """Labels of ``g`` after its ``n_swaps`` best swaps by first-order gain."""
        first = pairs[p_idx, 0] == g
        cur = maps_of(p_idx, g, L[g][None], Linv)[0]           # (deg, n)
        X = np.zeros((len(p_idx), n, n))
        X[np.arange(len(p_idx))[:, None], cols[None, :], cur] = 1.0
        gain = _swap_gains(cur, first, gradient(p_idx, X))[iu, ju]
        best = np.argpartition(-gain, n_swaps - 1)[:n_swaps] if n_swaps < len(iu) \
            else np.arange(len(iu))
        cand = np.repeat(L[g][None], len(best), axis=0)
        rows = np.arange(len(best))
        cand[rows, iu[best]] = L[g][ju[best]]
        cand[rows, ju[best]] = L[g][iu[best]]
        return cand

    Linv = _inverse_rows(L)
    current = Linv[pairs[:, 1][:, None], L[pairs[:, 0]]]       # map i -> j of every pair
    total = float(np.sum(score(np.arange(P), current)))
    history = [total]
    moves = {"anchor": 0, "swap": 0}
    for _ in range(max_sweeps):
        changed = False
        for g in range(N):
            p_idx = touching[g]
            if p_idx.size == 0:
                continue
            i, j = pairs[p_idx, 0], pairs[p_idx, 1]
            # re-anchor on each neighbour k: L_g = L_k o m_gk (m_gk = proposal or its inverse)
            props = proposals[p_idx]
            first = i == g
            nb = np.where(first, j, i)
            m_gk = np.where(first[:, None], props, _inverse_rows(props))
            anchors = L[nb[:, None], m_gk]
            swaps = swaps_of(p_idx, g, Linv) if n_swaps else np.empty((0, n), np.int64)
            cand, first_of = np.unique(np.vstack([L[g][None], anchors, swaps]), axis=0,
                                       return_index=True)
            maps = maps_of(p_idx, g, cand, Linv)               # (c, deg, n)
            s = score(np.tile(p_idx, len(cand)), maps.reshape(-1, n)).reshape(len(cand), -1)
            tot = s.sum(1)
            now = int(np.flatnonzero((cand == L[g]).all(1))[0])
            best = int(np.argmax(tot))
            if tot[best] > tot[now] * (1 + 1e-12) + 1e-12:
                moves["anchor" if first_of[best] <= len(anchors) else "swap"] += 1
                L[g] = cand[best]
                Linv[g, L[g]] = cols
                total += float(tot[best] - tot[now])
                changed = True
        history.append(total)
        if not changed:
            break
    return L, history, moves
