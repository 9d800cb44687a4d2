"""Batched pairwise matcher of the assignment kernel (transync.kernels._pairwise), issue #12."""

import warnings
from concurrent.futures import ThreadPoolExecutor

import numpy as np
import pytest

from transync.kernels import _pairwise
from transync.kernels._hks import hks_features
from transync.kernels._pairwise import (
    DUMMY_AFFINITY,
    PAIRWISE_MATCHERS,
    default_sigma2,
    match_pairs,
)
from transync.matching import rrwm, sm


def _random_graph(rng, n, p=0.35, asymmetric=True):
    """A random graph; ``asymmetric``: without isolated nodes or automorphisms (n >= 6)."""
    while True:
        A = np.triu(rng.random((n, n)) < p, 1).astype(float)
        A = A + A.T
        if not asymmetric:
            return A
        h = hks_features([A])[0]
        # no two nodes with equal signatures: no automorphism, a unique planted answer
        if A.sum(1).min() > 0 and len(np.unique(h.round(8), axis=0)) == n:
            return A


def _is_permutation(out):
    n = out.shape[1]
    return all(np.array_equal(np.sort(row), np.arange(n)) for row in out)


def _planted(rng, sizes):
    """Graphs 2k and 2k+1: graph 2k relabelled by perms[k]."""
    adjs, perms = [], []
    for n in sizes:
        A = _random_graph(rng, n)
        perm = rng.permutation(n)
        adjs += [A, A[np.ix_(perm, perm)]]
        perms.append(perm)
    return adjs, perms


@pytest.mark.parametrize("matcher", PAIRWISE_MATCHERS)
def test_planted_permutation_is_recovered(rng, matcher):
    adjs, perms = _planted(rng, [7, 9, 6])
    feats = hks_features(adjs)
    pairs = np.array([[0, 1], [2, 3], [4, 5], [0, 3]])
    out = match_pairs(feats, adjs, pairs, n=11, matcher=matcher)
    assert out.shape == (4, 11) and out.dtype == np.int32
    assert _is_permutation(out)
    for k, perm in enumerate(perms):
        n_k = len(perm)
        # node u of graph 2k is node perm^-1(u) of graph 2k+1; dummies go to dummies
        np.testing.assert_array_equal(perm[out[k, :n_k]], np.arange(n_k))
        assert set(out[k, n_k:]) == set(range(n_k, 11))


def _dense_problem(rng, n1, n2, sigma2=0.05):
    A1, A2 = _random_graph(rng, n1), _random_graph(rng, n2)
    h1, h2 = hks_features([A1, A2])
    m = max(n1, n2)
    P1, P2 = np.zeros((m, m)), np.zeros((m, m))
    P1[:n1, :n1], P2[:n2, :n2] = A1, A2
    node = np.full((m, m), DUMMY_AFFINITY)
    node[:n1, :n2] = np.exp(-((h1[:, None] - h2[None]) ** 2).sum(-1) / sigma2)
    # pygmtools layout: candidate (u, a) has index a * m + u
    K = np.kron(P2, P1) + np.diag(node.ravel(order="F"))
    return [h1, h2], [A1, A2], K, m


@pytest.mark.parametrize("sizes", [(8, 8), (6, 8)])
def test_rrwm_equals_pairwise_solver(rng, sizes):
    feats, adjs, K, m = _dense_problem(rng, *sizes)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")         # ConvergenceWarning at 50 iterations
        ref = rrwm(K, n1=m, n2=m, variant="pygmtools").assignment
    out = match_pairs(feats, adjs, [[0, 1]], n=m, matcher="rrwm", sigma2=0.05)
    # the dummy rows of graph 0 tie exactly with each other: compare its real nodes
    np.testing.assert_array_equal(out[0, :sizes[0]], ref[:sizes[0]])


@pytest.mark.parametrize("sizes", [(8, 8), (6, 8)])
def test_sm_equals_pairwise_solver(rng, sizes):
    feats, adjs, K, m = _dense_problem(rng, *sizes)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        ref = sm(K, n1=m, n2=m).assignment
    out = match_pairs(feats, adjs, [[0, 1]], n=m, matcher="sm", sigma2=0.05)
    np.testing.assert_array_equal(out[0, :sizes[0]], ref[:sizes[0]])


def test_node_matcher_is_the_optimal_linear_assignment(rng):
    """Brute force over all permutations of a tiny padded problem."""
    from itertools import permutations

    feats, adjs, K, m = _dense_problem(rng, 6, 7)
    node = np.diag(K).reshape(m, m, order="F")
    best = max(permutations(range(m)), key=lambda p: node[np.arange(m), list(p)].sum())
    out = match_pairs(feats, adjs, [[0, 1]], n=m, matcher="node", sigma2=0.05)
    np.testing.assert_array_equal(out[0], best)


@pytest.mark.parametrize("matcher", ["rrwm", "sm"])
def test_independent_of_executor_and_chunk_size(rng, matcher):
    # small graphs with automorphisms: exact ties that must be broken the same way every time
    adjs = [_random_graph(rng, n, asymmetric=False) for n in rng.integers(3, 10, size=9)]
    labels = [rng.integers(0, 2, size=len(A)) for A in adjs]
    feats = hks_features(adjs)
    pairs = np.stack(np.triu_indices(9, 1), axis=1)
    kw = dict(n=10, matcher=matcher, node_labels=labels)
    ref = match_pairs(feats, adjs, pairs, **kw)
    assert _is_permutation(ref)
    np.testing.assert_array_equal(match_pairs(feats, adjs, pairs, chunk_size=5, **kw), ref)
    with ThreadPoolExecutor(2) as pool:
        np.testing.assert_array_equal(
            match_pairs(feats, adjs, pairs, executor=pool, chunk_size=7, progress=False, **kw),
            ref)
    # a pair's result does not depend on the other pairs of the call
    np.testing.assert_array_equal(match_pairs(feats, adjs, pairs[[5, 2]], **kw), ref[[5, 2]])


@pytest.mark.parametrize("matcher", ["rrwm", "node"])
def test_chunk_plan_covers_every_pair_largest_first_within_memory(matcher):
    rng = np.random.default_rng(3)
    sizes = np.r_[rng.integers(2, 30, size=60), 120, 95]
    pairs = np.stack(np.triu_indices(len(sizes), 1), axis=1)
    order, bounds = _pairwise._chunk_plan(pairs, sizes, matcher, None)
    np.testing.assert_array_equal(np.sort(order), np.arange(len(pairs)))
    assert bounds[0] == 0 and bounds[-1] == len(pairs) and np.all(np.diff(bounds) > 0)
    m = np.maximum(sizes[pairs[order, 0]], sizes[pairs[order, 1]])
    assert np.all(np.diff(m) <= 0)                               # largest solve size first
    per_pair = 8 * _pairwise._STATE_ARRAYS[matcher] * m.astype(float) ** 2
    for s, e in zip(bounds[:-1], bounds[1:]):
        # the memory target holds at the chunk's largest size, unless the 8-pair minimum
        assert e - s <= 8 or (e - s) * per_pair[s] <= _pairwise._CHUNK_BYTES
    assert np.diff(bounds)[0] == 8 and len(bounds) - 1 >= 16    # costly pairs in small chunks
    order7, bounds7 = _pairwise._chunk_plan(pairs, sizes, matcher, 7)
    assert set(np.diff(bounds7)[:-1]) == {7}


def test_default_chunks_do_not_depend_on_the_executor(rng):
    # mixed sizes (one large graph): the default cut, not the executor, decides the chunks
    adjs = [_random_graph(rng, n, asymmetric=False) for n in [*rng.integers(3, 12, size=14), 26]]
    feats = hks_features(adjs)
    pairs = np.stack(np.triu_indices(len(adjs), 1), axis=1)
    kw = dict(n=26, matcher="rrwm")
    ref = match_pairs(feats, adjs, pairs, **kw)
    with ThreadPoolExecutor(3) as pool:
        np.testing.assert_array_equal(match_pairs(feats, adjs, pairs, executor=pool, **kw), ref)
    np.testing.assert_array_equal(match_pairs(feats, adjs, pairs, executor=2, **kw), ref)


def test_labels_restrict_the_node_matching(rng):
    """Equal features: only the labels (a planted relabelling) decide."""
    perm = rng.permutation(6)
    lab = np.arange(6)
    A = np.zeros((6, 6))
    feats = [np.ones((6, 2)), np.ones((6, 2))]
    out = match_pairs(feats, [A, A], [[0, 1]], n=6, matcher="node",
                      node_labels=[lab, lab[perm]])
    np.testing.assert_array_equal(perm[out[0]], np.arange(6))


def test_dummies_absorb_unmatched_nodes():
    """A node whose label the other graph lacks goes to a dummy, not to a real node."""
    feats = [np.zeros((4, 1)), np.zeros((3, 1))]
    out = match_pairs(feats, [np.zeros((4, 4)), np.zeros((3, 3))], [[0, 1]], n=5,
                      matcher="node", node_labels=[np.array([0, 0, 1, 0]), np.zeros(3, int)])
    assert out[0, 2] == 3                       # graph 1's dummy slot
    assert sorted(out[0, [0, 1, 3]]) == [0, 1, 2] and out[0, 4] == 4


def test_default_sigma2():
    h = [np.array([[0.0], [1.0]]), np.array([[3.0]])]
    assert default_sigma2(h) == 4.0                   # squared distances 1, 9, 4
    assert default_sigma2([np.ones((3, 2))]) == 1.0    # all equal: fallback
    big = [np.arange(1500.0)[:, None]]
    assert default_sigma2(big) == default_sigma2(big)
    assert default_sigma2(big, rng=0) == default_sigma2(big, rng=np.random.default_rng(0))


def test_empty_pairs():
    A = np.zeros((2, 2))
    out = match_pairs([np.ones((2, 1))] * 2, [A, A], np.zeros((0, 2), int), n=3)
    assert out.shape == (0, 3) and out.dtype == np.int32


def test_validation():
    A = np.array([[0.0, 1.0], [1.0, 0.0]])
    h = np.ones((2, 1))
    ok = dict(features=[h, h], adjacencies=[A, A], pairs=[[0, 1]], n=2)

    def call(**kw):
        return match_pairs(**{**ok, **kw})

    with pytest.raises(ValueError, match="same length"):
        call(adjacencies=[A])
    with pytest.raises(ValueError, match=r"`adjacencies\[1\]` must have shape"):
        call(adjacencies=[A, np.zeros((3, 3))])
    with pytest.raises(ValueError, match="`n` must be at least the largest graph: graph 0"):
        call(features=[np.ones((3, 1)), h], adjacencies=[np.zeros((3, 3)), A])
    with pytest.raises(ValueError, match="`matcher` must be one of"):
        call(matcher="ga")
    with pytest.raises(ValueError, match="`sigma2` must be finite and > 0"):
        call(sigma2=-1.0)
    with pytest.raises(ValueError, match="`dummy_affinity` must be finite and >= 0"):
        call(dummy_affinity=-0.1)
    with pytest.raises(ValueError, match=r"`pairs` must hold graph indices in \[0, 2\)"):
        call(pairs=[[0, 2]])
    with pytest.raises(TypeError, match="`pairs` must hold integer"):
        call(pairs=[[0.5, 1.0]])
    with pytest.raises(ValueError, match=r"`features\[1\]` must have 1 columns"):
        call(features=[h, np.ones((2, 2))])
    with pytest.raises(ValueError, match="symmetric"):
        call(adjacencies=[A, np.array([[0.0, 1.0], [0.0, 0.0]])])
    with pytest.raises(ValueError, match=r"`node_labels\[0\]` must have length 2"):
        call(node_labels=[np.zeros(3, int), np.zeros(2, int)])
    with pytest.raises(TypeError, match="`features` must be a list or tuple"):
        call(features=np.ones((2, 2, 1)))
    with pytest.raises(ValueError, match="`chunk_size` must be >= 1"):
        call(chunk_size=0)
    with pytest.raises(TypeError, match="`progress` must be a bool"):
        call(progress="yes")


@pytest.mark.dataset("tu")
def test_mutag_relabelled_copies_are_matched_isomorphically(rng):
    datasets = pytest.importorskip("transync.datasets")
    try:
        graphs = list(datasets.load_tu("MUTAG").graphs[:4])
    except (ImportError, AttributeError):
        pytest.skip("transync.datasets.load_tu unavailable")
    adjs, labels = [], []
    for g in graphs:
        perm = rng.permutation(g.n_nodes)
        adjs += [g.adjacency, g.adjacency[np.ix_(perm, perm)]]
        labels += [g.node_labels, g.node_labels[perm]]
    n = max(len(A) for A in adjs)
    pairs = np.array([[2 * k, 2 * k + 1] for k in range(len(graphs))])
    out = match_pairs(hks_features(adjs), adjs, pairs, n=n, matcher="rrwm", node_labels=labels)
    for k, (i, j) in enumerate(pairs):
        m = len(adjs[i])
        a = out[k, :m]
        assert np.all(a < m)                                        # real to real
        np.testing.assert_array_equal(adjs[j][np.ix_(a, a)], adjs[i])   # an isomorphism
        np.testing.assert_array_equal(labels[j][a], labels[i])
