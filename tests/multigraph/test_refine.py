"""Consistent refinement: exact first-order swap gains, planted recovery, monotone score."""

import functools

import numpy as np
import pytest

from transync.datasets import make_graph_collection
from transync.matching import gaussian_edge_affinity
from transync.multigraph import PairAffinities
from transync.multigraph._refine import _inverse_rows, _swap_gains, refine_consistent

AFF = functools.partial(gaussian_edge_affinity, sigma2=0.05)


def _problem(n_graphs=4, n=6, deformation=0.0, directed=False, seed=0):
    p = make_graph_collection(n_graphs=n_graphs, n_inliers=n, deformation=deformation,
                              shuffle=True, rng=seed)
    graphs = p.graphs
    if directed:                        # asymmetric K: an edge's attribute depends on direction
        rng = np.random.default_rng(seed)
        graphs = [type(g)(adjacency=(g.adjacency > 0).astype(float),
                          edge_features=g.edge_features * rng.uniform(0.5, 1.5, (n, n)),
                          directed=True) for g in graphs]
    i, j = np.triu_indices(n_graphs, 1)
    pairs = np.column_stack([i, j]).astype(np.int64)
    return p, PairAffinities.from_graphs(graphs, pairs, AFF), pairs


def _maps(L, pairs):
    Linv = _inverse_rows(L)
    return Linv[pairs[:, 1][:, None], L[pairs[:, 0]]]


def _gradient(aff):
    def gradient(p_idx, X):
        return aff._product(X, p_idx) + aff._product(X, p_idx, True)
    return gradient


@pytest.mark.parametrize("directed", [False, True])
def test_swap_gains_are_the_exact_first_order_term(directed):
    """score(x + d) - score(x) = d^T (K + K^T) x + d^T K d for every swap of one graph's slots,
    summed over the pairs that touch it (with the graph first and second)."""
    _, aff, pairs = _problem(n_graphs=4, n=6, deformation=0.1, directed=directed)
    rng = np.random.default_rng(1)
    L = np.stack([rng.permutation(6) for _ in range(4)])
    g = 1                                               # second in (0, 1), first in (1, 2)...
    p_idx = np.flatnonzero((pairs == g).any(1))
    cur = _maps(L, pairs)[p_idx]
    n = 6
    X = np.zeros((len(p_idx), n, n))
    X[np.arange(len(p_idx))[:, None], np.arange(n), cur] = 1.0
    gains = _swap_gains(cur, pairs[p_idx, 0] == g, _gradient(aff)(p_idx, X))
    base = aff.score_assignments(p_idx, cur).sum()
    for u in range(n):
        for v in range(u + 1, n):
            L2 = L.copy()
            L2[g, [u, v]] = L[g, [v, u]]
            cur2 = _maps(L2, pairs)[p_idx]
            X2 = np.zeros_like(X)
            X2[np.arange(len(p_idx))[:, None], np.arange(n), cur2] = 1.0
            D = X2 - X
            quad = np.einsum("pij,pij->", D, aff._product(D, p_idx))
            exact = aff.score_assignments(p_idx, cur2).sum() - base
            # the products use the affinity's factorization (error ~1e-9 here), the scores the
            # exact Gaussian kernel
            assert gains[u, v] == pytest.approx(exact - quad, abs=1e-6)
            assert gains[v, u] == pytest.approx(gains[u, v], abs=1e-12)


def test_swaps_recover_a_planted_swap_that_re_anchoring_cannot():
    """Zero noise; graph 2 has two nodes' slots exchanged and every proposal is the map of that
    configuration, so no re-anchoring helps: the swap move restores the truth."""
    p, aff, pairs = _problem(n_graphs=5, n=8, seed=3)
    truth = np.stack(p.ground_truth.labels)
    start = truth.copy()
    start[2, [1, 5]] = truth[2, [5, 1]]
    proposals = _maps(start, pairs)
    L, hist, moves = refine_consistent(start, pairs, proposals, aff.score_assignments)
    assert np.array_equal(L, start) and moves == {"anchor": 0, "swap": 0}
    L, hist, moves = refine_consistent(start, pairs, proposals, aff.score_assignments,
                                       gradient=_gradient(aff))
    assert np.array_equal(_maps(L, pairs), _maps(truth, pairs))
    assert moves["swap"] >= 1 and hist[-1] > hist[0]
    assert hist[-1] == pytest.approx(aff.score_assignments(np.arange(len(pairs)),
                                                           _maps(truth, pairs)).sum())


@pytest.mark.parametrize("seed", range(4))
def test_refinement_never_lowers_the_score_and_stays_consistent(seed):
    _, aff, pairs = _problem(n_graphs=6, n=7, deformation=0.2, seed=seed)
    rng = np.random.default_rng(seed)
    start = np.stack([rng.permutation(7) for _ in range(6)])
    proposals = np.stack([rng.permutation(7) for _ in range(len(pairs))])
    L, hist, moves = refine_consistent(start, pairs, proposals, aff.score_assignments,
                                       gradient=_gradient(aff), n_swaps=3)
    assert np.all(np.diff(hist) >= -1e-9)
    assert np.all(np.sort(L, axis=1) == np.arange(7))
    total = aff.score_assignments(np.arange(len(pairs)), _maps(L, pairs)).sum()
    assert total == pytest.approx(hist[-1])
    assert sum(moves.values()) > 0


def test_no_swaps_without_a_gradient_or_with_n_swaps_zero():
    p, aff, pairs = _problem(n_graphs=4, n=6, seed=5)
    truth = np.stack(p.ground_truth.labels)
    start = truth.copy()
    start[0, [0, 1]] = truth[0, [1, 0]]
    proposals = _maps(start, pairs)
    L, _, moves = refine_consistent(start, pairs, proposals, aff.score_assignments,
                                    gradient=_gradient(aff), n_swaps=0)
    assert np.array_equal(L, start) and moves["swap"] == 0
