"""The kernels' shared input checks (``transync.kernels._checks``): bad inputs, named errors."""

from __future__ import annotations

import numpy as np
import pytest

from transync.graphs import Graph
from transync.kernels._checks import (
    check_adjacency,
    check_feature_list,
    check_graph_list,
    check_int_array,
    check_label_array,
    check_node_labels,
    check_sequence,
)

EDGE = np.array([[0.0, 1.0], [1.0, 0.0]])


# --------------------------------------------------------------------------- sequences

@pytest.mark.parametrize("bad", ["ab", b"ab", np.zeros((2, 2)), 3, None, {0: EDGE},
                                 Graph(adjacency=EDGE)])
def test_sequence_wrong_type(bad):
    with pytest.raises(TypeError, match=r"`things` must be a list of things, got"):
        check_sequence(bad, "things", "a list of things")


def test_sequence_single_graph_and_arrays():
    with pytest.raises(TypeError, match=r"`things` .*single Graph \(wrap it in a list\)"):
        check_sequence(Graph(adjacency=EDGE), "things", "a list", arrays=True)
    assert len(check_sequence(np.zeros((3, 2)), "things", "a list", arrays=True)) == 3
    assert check_sequence((1, 2), "things", "a list") == [1, 2]


def test_sequence_empty():
    with pytest.raises(ValueError, match="`things` must hold at least one graph, got an empty"):
        check_sequence([], "things", "a list")
    assert check_sequence([], "things", "a list", allow_empty=True) == []


# --------------------------------------------------------------------------- features

def test_feature_list_bad_inputs():
    with pytest.raises(TypeError, match="`features` must be a list or tuple .*sequence"):
        check_feature_list(np.ones((2, 3, 1)))
    with pytest.raises(ValueError, match="`features` must hold at least one graph"):
        check_feature_list([])
    with pytest.raises(ValueError, match=r"`features\[1\]` must have 2 dimensions"):
        check_feature_list([np.ones((2, 1)), np.ones(2)])
    with pytest.raises(ValueError, match=r"`features\[1\]` must have 1 columns"):
        check_feature_list([np.ones((2, 1)), np.ones((2, 2))])
    with pytest.raises(ValueError, match=r"`features\[0\]` must describe at least one node"):
        check_feature_list([np.ones((0, 1))])
    with pytest.raises(ValueError, match=r"`features\[0\]` must be finite"):
        check_feature_list([np.full((2, 1), np.nan)])
    with pytest.raises(TypeError, match=r"`feats\[0\]` must be an array"):
        check_feature_list([None], "feats")


def test_feature_list_one_dimensional():
    out = check_feature_list([np.arange(3.0), np.ones((2, 1))], ndim=(1, 2))
    assert [F.shape for F in out] == [(3, 1), (2, 1)]


# --------------------------------------------------------------------------- adjacencies

@pytest.mark.parametrize("bad, exc, match", [
    ("ab", TypeError, "`adj` must be an array"),
    (np.zeros(3), ValueError, "`adj` must have 2 dimensions"),
    (np.zeros((2, 3)), ValueError, r"`adj` must be a square \(n, n\) adjacency"),
    (np.zeros((0, 0)), ValueError, r"`adj` must be a square \(n, n\) adjacency with n >= 1"),
    (np.array([[0.0, -1.0], [-1.0, 0.0]]), ValueError, "`adj` must be non-negative"),
    (np.array([[0.0, 1.0], [0.0, 0.0]]), ValueError, "`adj` must be symmetric"),
    (np.array([[0.0, np.inf], [np.inf, 0.0]]), ValueError, "`adj` must be finite"),
    (Graph(adjacency=np.array([[0.0, 1.0], [0.0, 0.0]]), directed=True), ValueError,
     "`adj` must be an undirected graph"),
])
def test_adjacency_bad_inputs(bad, exc, match):
    with pytest.raises(exc, match=match):
        check_adjacency(bad, "adj")


def test_adjacency_node_count_and_symmetry_modes():
    with pytest.raises(ValueError, match=r"`adj` must have shape \(3, 3\)"):
        check_adjacency(EDGE, "adj", n=3)
    weighted = np.array([[0.0, 2.0], [1.0, 0.0]])         # symmetric edges, asymmetric weights
    assert check_adjacency(weighted, "adj", edges_only=True) is not None
    with pytest.raises(ValueError, match="`adj` must be symmetric"):
        check_adjacency(weighted, "adj")
    noisy = EDGE + np.array([[0.0, 1e-12], [0.0, 0.0]])   # symmetric up to rounding
    out = check_adjacency(noisy, "adj")
    np.testing.assert_array_equal(out, out.T)
    np.testing.assert_array_equal(check_adjacency(Graph(adjacency=EDGE), "adj"), EDGE)


def test_graph_list_bad_inputs():
    with pytest.raises(TypeError, match="`graphs` must be a sequence"):
        check_graph_list(EDGE)
    with pytest.raises(TypeError, match="`graphs` .*single Graph"):
        check_graph_list(Graph(adjacency=EDGE))
    with pytest.raises(ValueError, match="`graphs` must hold at least one graph"):
        check_graph_list([])
    assert check_graph_list([], allow_empty=True) == []
    with pytest.raises(ValueError, match=r"`graphs\[1\]` must be a square"):
        check_graph_list([EDGE, np.zeros((2, 3))])
    with pytest.raises(ValueError, match=r"`graphs\[0\]` must be non-negative"):
        check_graph_list([-EDGE])


# --------------------------------------------------------------------------- node labels

@pytest.mark.parametrize("bad", [np.array([0.0, 1.0]), np.array([0.0, np.nan]),
                                 np.array(["a", "b"]), np.array([0, 1], dtype=object)])
def test_label_array_non_integer_is_type_error(bad):
    with pytest.raises(TypeError, match=r"`lab` must hold integer labels, got dtype"):
        check_label_array(bad, "lab", 2)


def test_label_array_shapes():
    with pytest.raises(ValueError, match=r"`lab` must have length 3 \(the graph's node count\), "
                                         r"got 2"):
        check_label_array([0, 1], "lab", 3)
    with pytest.raises(ValueError, match="`lab` must have 1 dimensions"):
        check_label_array(np.zeros((2, 1), int), "lab", 2)
    out = check_label_array(np.array([True, False]), "lab", 2)
    assert out.dtype == np.int64 and out.tolist() == [1, 0]


def test_node_labels_bad_inputs():
    with pytest.raises(TypeError, match="`node_labels` must be a sequence"):
        check_node_labels("ab", [2])
    with pytest.raises(TypeError, match="`node_labels` must be a sequence"):
        check_node_labels(3, [2])
    with pytest.raises(ValueError, match=r"`node_labels` must have one entry per graph \(2\), "
                                         r"got 1"):
        check_node_labels([np.zeros(2, int)], [2, 3])
    with pytest.raises(ValueError, match=r"`node_labels` must have one entry per graph"):
        check_node_labels([], [2])
    with pytest.raises(ValueError, match=r"`node_labels\[1\]` must have length 3"):
        check_node_labels([np.zeros(2, int), np.zeros(2, int)], [2, 3])
    with pytest.raises(TypeError, match=r"`labs\[0\]` must hold integer labels"):
        check_node_labels([np.zeros(2)], [2], "labs")
    with pytest.raises(TypeError, match=r"`node_labels\[0\]` must be an array, got None"):
        check_node_labels([None], [2])


def test_node_labels_arrays_and_missing():
    out = check_node_labels(np.zeros((2, 3), np.int32), [3, 3])
    assert [lab.dtype for lab in out] == [np.int64, np.int64]
    out = check_node_labels([None, [1, 2]], [1, 2], missing_ok=True)
    assert out[0] is None and out[1].tolist() == [1, 2]


# --------------------------------------------------------------------------- integer arrays

def test_int_array_bad_inputs():
    with pytest.raises(TypeError, match=r"`pairs` must hold integers, got dtype float64"):
        check_int_array([[0.5, 1.0]], "pairs")
    with pytest.raises(ValueError, match="`pairs` must have 2 dimensions"):
        check_int_array([0, 1], "pairs", 2)
    with pytest.raises(TypeError, match="`pairs` must be an array, got None"):
        check_int_array(None, "pairs")
    assert check_int_array([], "pairs").dtype == np.int64
    a32 = np.zeros((2, 2), np.int32)
    assert check_int_array(a32, "a", 2, keep_dtype=True) is a32
    assert check_int_array(a32, "a", 2).dtype == np.int64


def test_feature_values_beyond_the_limit_and_widths_near_float_limits():
    """Huge features, tiny or huge widths: named refusals, never an overflowed (NaN) kernel."""
    from transync.kernels import (aligned_features, default_sigma2, hks_oa_kernel,
                                  hks_mean_kernel, match_pairs, median_gamma)
    from transync.kernels._checks import FEATURE_LIMIT, SIGMA2_MIN, check_width

    big = [np.array([[0.0], [1.0]]), np.array([[2e100]])]
    for fn in (default_sigma2, hks_oa_kernel, hks_mean_kernel):
        with pytest.raises(ValueError, match=r"`features\[1\]` has values up to 2e\+100"):
            fn(big)
    assert FEATURE_LIMIT == 1e100
    close = [np.array([[0.0], [1e-160]]), np.array([[0.0]])]
    with pytest.raises(ValueError, match="in `features` are too close"):
        default_sigma2(close)
    # aligned, beside the real-node indicator (1.0) the same features are rounding noise:
    # distance 0, the fallback width 1 (no Gaussian of width 1e-320 on the Gram's rounding)
    X = aligned_features([close[0], close[0][::-1]], np.array([[0, 1], [0, 1]]))
    assert median_gamma(X) == 1.0
    with pytest.raises(ValueError, match=r"`sigma2` must be at least 1e-300"):
        hks_oa_kernel([np.array([[0.0], [1.0]])] * 2, sigma2=1e-310)
    with pytest.raises(ValueError, match=r"`sigma2` must be at least"):
        match_pairs([np.zeros((2, 1))] * 2, [np.zeros((2, 2))] * 2, [[0, 1]], n=2,
                    sigma2=SIGMA2_MIN / 10)
    with pytest.raises(ValueError, match=r"`gamma` must be at most 1e\+300"):
        hks_mean_kernel([np.zeros((2, 1))] * 2, kernel="rbf", gamma=1e301)
    assert check_width(SIGMA2_MIN, "sigma2") == SIGMA2_MIN
    # the smallest width accepted: far nodes get affinity exactly 0, no warning, no NaN
    with __import__("warnings").catch_warnings():
        __import__("warnings").simplefilter("error")
        K = hks_oa_kernel([np.array([[0.0], [1e9]]), np.array([[1e9], [0.0]])],
                          sigma2=SIGMA2_MIN)
    np.testing.assert_allclose(K, 1.0)


@pytest.mark.parametrize("name", ["hks_mean_kernel", "default_sigma2", "graph_descriptors",
                                  "hks_oa_kernel"])
def test_zero_width_features_are_refused_by_name(name):
    """Node features with no column: "zero-size array to reduction operation maximum"."""
    from transync import kernels

    with pytest.raises(ValueError, match=r"`features\[0\]` must have at least one feature "
                                         r"column, got shape \(2, 0\)"):
        getattr(kernels, name)([np.ones((2, 0)), np.ones((3, 0))])


def test_rng_is_checked_whatever_the_size():
    """A bad `rng` passed on small inputs (no sampling) and failed on large ones."""
    from transync.kernels import default_sigma2, median_gamma

    X = np.random.default_rng(0).normal(size=(70, 3, 2))
    for fn, arg in ((median_gamma, X[:10]), (median_gamma, X),
                    (default_sigma2, [X[0]]), (default_sigma2, list(X))):
        with pytest.raises(TypeError, match="`rng` must be None, an int or"):
            fn(arg, rng="x")


def test_tiny_weights_do_not_pass_for_symmetric():
    """numpy.allclose's absolute 1e-8 tolerance took a 3x asymmetric adjacency of weights ~1e-9
    for symmetric (Graph refused the same matrix): the symmetry test is relative now."""
    from transync.kernels import heat_kernel_signature

    A = np.array([[0.0, 1e-9, 0.0], [3e-9, 0.0, 1e-9], [0.0, 1e-9, 0.0]])
    for scale in (1.0, 1e9):
        with pytest.raises(ValueError, match="must be symmetric"):
            heat_kernel_signature(A * scale, [1.0])
    S = np.array([[0.0, 1e-9, 0.0], [1e-9 * (1 + 1e-12), 0.0, 1e-9], [0.0, 1e-9, 0.0]])
    assert np.isfinite(heat_kernel_signature(S, [1.0])).all()     # rounding noise: accepted
