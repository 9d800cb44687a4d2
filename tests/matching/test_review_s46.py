"""Inputs of the pairwise layer that a fuzz review (2026-11-29) found mishandled: silent wrong
answers, NaN results, hangs or raw NumPy errors. Each test fails on the code before its fix."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from transync.exceptions import DegenerateInputError
from transync.graphs import Graph
from transync.matching import (
    Affinity,
    DenseAffinity,
    RRWMStepper,
    SeparableAffinity,
    SMStepper,
    annealing_levels,
    default_beta_max,
    gaussian_edge_affinity,
    match_graphs,
    prefers_separable,
    sinkhorn_batch,
    sm,
)


def _planted(n=6, seed=0):
    rng = np.random.default_rng(seed)
    g1 = Graph.from_points(rng.random((n, 2)), edges="full")
    perm = rng.permutation(n)
    return g1, g1.permute(perm), perm


@pytest.mark.parametrize("scale", [1e-310, 1e-200, 1.0, 1e150, 1e200, 1.7e308])
@pytest.mark.parametrize("stepper", [SMStepper, RRWMStepper])
def test_a_huge_iterate_is_rescaled_not_collapsed(stepper, scale):
    """SM and RRWM take an iterate of any scale. At 1e200 SM's ||K x|| overflowed: the iterate
    became 0, converged=True, eigenvalue NaN and an arbitrary assignment (at 1e-200 it
    underflowed, with the same result); RRWM's sum overflowed with a RuntimeWarning at
    1.7e308."""
    g1, g2, perm = _planted()
    st = stepper(gaussian_edge_affinity(g1, g2))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        st.set_iterate(np.full((6, 6), scale))
        while not st.done:
            st.step()
    r = st.result()
    np.testing.assert_array_equal(perm[r.assignment], np.arange(6))
    assert np.isfinite(r.soft).all() and r.converged
    if stepper is SMStepper:
        assert np.isfinite(r.info["eigenvalue"]) and r.info["eigenvalue"] > 0


def test_sinkhorn_batch_warm_start_scale_is_free_and_exact():
    """A warm start's overall size does not matter (u absorbs it): at 1e308 or 5e-324 the
    scalings overflowed and X came back all NaN. It is brought near 1 by a power of two, so that
    a normal warm start gives the same matrices bit for bit as before."""
    rng = np.random.default_rng(1)
    A = rng.random((3, 4, 5)) + 0.1
    first = sinkhorn_batch(A, tol=1e-9)
    base = sinkhorn_batch(A * 1.01, tol=1e-9, warm_start=first.scaling)
    for factor in (2.0 ** 40, 2.0 ** -60):
        again = sinkhorn_batch(A * 1.01, tol=1e-9, warm_start=first.scaling * factor)
        np.testing.assert_array_equal(again.X, base.X)
    cold = sinkhorn_batch(A, tol=1e-9)
    for ws in (np.full((3, 5), 1e308), np.full((3, 5), 5e-324)):
        out = sinkhorn_batch(A, tol=1e-9, warm_start=ws)
        assert np.isfinite(out.X).all() and out.converged.all()
        np.testing.assert_allclose(out.X, cold.X, atol=1e-8)


def test_sinkhorn_batch_refuses_what_overflows_instead_of_returning_nan():
    """Entries within the documented bounds can still overflow the scalings of slack="none";
    the result was all NaN with converged=False. Now a DegenerateInputError pointing to the
    log domain, which handles it."""
    B = np.array([[[1e297, 1e-300, 1e-300], [1e-300, 1e-300, 1e297]]])
    with pytest.raises(DegenerateInputError, match=r"overflowed on 1 of 1 matrices .*"
                                                   r"domain='log'"):
        sinkhorn_batch(B, slack="none", tol=1e-9)
    logged = sinkhorn_batch(np.log(B), slack="none", domain="log", tol=1e-9)
    assert np.isfinite(logged.X).all()
    assert np.isfinite(sinkhorn_batch(B, slack="mass", tol=1e-9).X).all()


def test_linear_methods_refuse_an_affinity_without_unary_term():
    """hungarian / sinkhorn read the diagonal of `affinity`; an edge-only affinity has none and
    the identity came back as a converged matching. With `node_affinity` given they use it, as
    documented; the quadratic methods refuse both."""
    g1, g2, perm = _planted()
    aff = gaussian_edge_affinity(g1, g2)
    for method in ("hungarian", "sinkhorn"):
        with pytest.raises(ValueError, match=rf"method='{method}' scores nodes by the diagonal "
                                             r"of `affinity` .* all zero"):
            match_graphs(g1, g2, method=method, affinity=aff)
    S = np.eye(6)[:, perm]
    with pytest.raises(ValueError, match=r"not as `node_affinity`, when `affinity` is given"):
        match_graphs(g1, g2, method="rrwm", affinity=aff, node_affinity=S)
    res = match_graphs(g1, g2, method="hungarian", affinity=aff, node_affinity=S)
    np.testing.assert_array_equal(perm[res.assignment], np.arange(6))
    with_unary = gaussian_edge_affinity(g1, g2, node_affinity=np.eye(6)[:, perm])
    res = match_graphs(g1, g2, method="hungarian", affinity=with_unary)
    np.testing.assert_array_equal(perm[res.assignment], np.arange(6))


def test_graph_symmetry_is_judged_relative_to_the_weights():
    """allclose's absolute tolerance 1e-8 took a directed 3-cycle of weights ~1e-9 for
    symmetric and averaged it; the same matrix times 1e9 was refused."""
    A = np.array([[0.0, 4e-9, 0.0], [0.0, 0.0, 3e-9], [1e-9, 0.0, 0.0]])
    for scale in (1.0, 1e9):
        with pytest.raises(ValueError, match="`adjacency` must be symmetric"):
            Graph(A * scale)
        assert Graph(A * scale, directed=True).directed
    E = np.array([[0, 1e-10, 1e-10], [9e-9, 0, 1e-10], [1e-10, 1e-10, 0]])
    with pytest.raises(ValueError, match="`edge_features` must be symmetric"):
        Graph(np.ones((3, 3)) - np.eye(3), edge_features=E)
    S = np.array([[0, 1e-9, 2e-9], [1e-9, 0, 3e-9], [2e-9, 3e-9, 0]])
    noisy = S.copy()
    noisy[0, 1] *= 1 + 1e-12                 # rounding noise at this scale: made symmetric
    g = Graph(noisy)
    np.testing.assert_array_equal(g.adjacency, g.adjacency.T)


@pytest.mark.parametrize("backend", ["dense", "factorized", "separable", "sparse"])
def test_affinity_products_check_their_argument(backend):
    """matvec / rmatvec raised a raw IndexError (factorized, 1-d X), accepted a (3, 4) X for a
    3 x 3 problem, or cast a complex X to real with a ComplexWarning."""
    g1, g2, _ = _planted(3)
    aff = gaussian_edge_affinity(g1, g2, backend=backend)
    X = np.random.default_rng(0).random((3, 3))
    expected = aff.to_dense() @ X.ravel(order="F")
    np.testing.assert_allclose(aff.matvec(X).ravel(order="F"), expected, atol=1e-8)
    for bad in (X.ravel(), np.ones((3, 4))):
        for product in (aff.matvec, aff.rmatvec):
            with pytest.raises(ValueError, match=r"`X` must have shape \(n1, n2\) = \(3, 3\)"):
                product(bad)
    for bad in (X + 1j, None, "abc"):
        with pytest.raises(TypeError, match="`X` must be a real array"):
            aff.matvec(bad)
    assert aff.matvec(np.eye(3, dtype=int)).dtype == float


class _Mine(Affinity):
    def __init__(self, n1, n2, complex_output=False):
        self.n1, self.n2, self.complex_output = n1, n2, complex_output

    def matvec(self, X):
        return np.ones((3, 4)) * (1j if self.complex_output else 1.0)

    def diag(self):
        return np.ones((3, 4))

    def to_dense(self):
        return np.ones((12, 12))


@pytest.mark.parametrize("n1, exc, match", [
    (0, ValueError, r"`K\.n1` must be >= 1, got 0"),
    (-1, ValueError, r"`K\.n1` must be >= 1, got -1"),
    (2.5, TypeError, r"`K\.n1` must be an int, got float 2\.5"),
    (None, TypeError, r"`K\.n1` must be an int, got NoneType"),
])
def test_a_user_affinity_declares_valid_sizes(n1, exc, match):
    """A user's Affinity subclass with n1 = 0 gave a raw ZeroDivisionError, -1 NumPy's
    "negative dimensions", 2.5 was truncated to 2, None a bare int() TypeError."""
    with pytest.raises(exc, match=match):
        sm(_Mine(n1, 4))
    assert sm(_Mine(3, 4)).assignment.shape == (3,)
    with pytest.raises(TypeError, match=r"`K`\.matvec\(\) \(a _Mine\) must return a real "
                                        r"array, got a complex one"):
        sm(_Mine(3, 4, complex_output=True))


def test_separable_affinity_refuses_a_negative_k():
    """-(F (x) G) was accepted; sm and pf rescaled by its negative column sums and returned
    "converged" results of the flipped problem. DenseAffinity refused the same K."""
    rng = np.random.default_rng(0)
    F, G = rng.random((1, 3, 3)), rng.random((1, 4, 4))
    with pytest.raises(ValueError, match=r"`F`, `G` give a K with negative entries"):
        SeparableAffinity(None, -F, G)
    with pytest.raises(ValueError, match="non-negative"):
        DenseAffinity(-SeparableAffinity(None, F, G).to_dense(), 3, 4)
    # an expansion's small negative entries within its error bound are accepted
    G2 = np.concatenate([G, -1e-9 * np.ones((1, 4, 4))])
    F2 = np.concatenate([F, np.ones((1, 3, 3))])
    aff = SeparableAffinity(None, F2, G2, max_error=1e-8)
    assert aff.rank == 2


def test_schedule_and_cost_helpers_check_their_arguments():
    """annealing_levels(1, 10, 0.5) returned -2, prefers_separable wrapped int64 at 2**40 and
    raised a raw OverflowError on 1e30, default_beta_max a raw TypeError on None."""
    assert annealing_levels(0.5, 10.0, 1.075) == 43
    with pytest.raises(ValueError, match=r"`beta_rate` must be > 1, got 0\.5"):
        annealing_levels(1, 10, 0.5)
    with pytest.raises(ValueError, match=r"`beta_max` must be >= beta0=1\.0, got 0\.5"):
        annealing_levels(1, 0.5, 2)
    with pytest.raises(TypeError, match="`beta0` must be a real number"):
        annealing_levels("a", 1, 2)
    assert not prefers_separable(2**40, 2**40, 1, 1)          # n^3 >> m1 m2: factorized
    assert prefers_separable(20, 20, 380, 380)
    with pytest.raises(TypeError, match="`n1` must hold counts of nodes or edges"):
        prefers_separable(1e30, 1, 1, 1)
    with pytest.raises(ValueError, match="`n1` must be >= 0, got -5"):
        prefers_separable(-5, 3, 1, 1)
    assert default_beta_max(30, 24) == 30.0
    with pytest.raises(TypeError, match="`n1` must be an int, got NoneType"):
        default_beta_max(None, 2)
    with pytest.raises(ValueError, match="`n1` must be <= "):
        default_beta_max(10**400, 1)


def test_zero_width_node_features_are_refused_by_the_node_affinity():
    """node_features of shape (n, 0) gave "Mean of empty slice" warnings and an all-ones unary
    term, so hungarian returned an arbitrary matching."""
    g = Graph(np.ones((3, 3)) - np.eye(3), node_features=np.zeros((3, 0)))
    with pytest.raises(ValueError, match=r"`g1\.node_features` and `g2\.node_features` have no "
                                         r"columns"):
        match_graphs(g, g, method="hungarian")
