"""Agreement with pygmtools (numpy backend) on identical inputs.

What is compared, exactly:

* affinity: pygmtools' ``build_aff_mat`` + ``gaussian_aff_fn(sigma=sigma2)`` on the edge lengths of
  two fully connected graphs equals transync's dense backend entrywise (1e-12), and the separable
  expansion to within its reported ``max_error``;
* ``sm``: both run the same power iteration (uniform start, ``max_iter=50``, stop when the unit
  vector moves less than 1e-5), so the soft eigenvector matrices agree to 1e-10 and the
  Hungarian-rounded assignments are identical, on planted and on noisy problems;
* ``rrwm``: pygmtools' variant differs from the original (jump weight ``alpha`` instead of the
  walk weight ``c``, fixed 20 Sinkhorn half-sweeps, no conflict removal, ``max_iter=50``, rounds
  the mixture); with its defaults and transync's original defaults, both recover the planted
  solution of easy problems. ``rrwm(variant="pygmtools")`` runs pygmtools' loop: run for the same
  50 iterations its rounded matrix equals pygmtools' output to 1e-10, and with its own stopping
  rule its assignments are identical on noisy problems with outliers in both graphs and with
  unequal sizes;
* ``ipfp``: both implement Leordeanu et al.'s iteration from the uniform start; on easy problems
  both recover the planted solution, and transync's objective is never below pygmtools'.
"""

from __future__ import annotations

import functools
import warnings

import numpy as np
import pytest

pygm = pytest.importorskip("pygmtools")
pygm.set_backend("numpy")

from transync.exceptions import ConvergenceWarning  # noqa: E402
from transync.graphs import Graph  # noqa: E402
from transync.matching import gaussian_edge_affinity, ipfp, rrwm, sm  # noqa: E402


def _problem(rng, n, deformation):
    P = rng.random((n, 2))
    perm = rng.permutation(n)
    Q = (P + deformation * rng.standard_normal(P.shape))[perm]
    return Graph.from_points(P, edges="full"), Graph.from_points(Q, edges="full"), np.argsort(perm)


def _pygm_K(g1, g2, sigma2):
    c1, e1 = pygm.utils.dense_to_sparse(g1.distances())
    c2, e2 = pygm.utils.dense_to_sparse(g2.distances())
    fn = functools.partial(pygm.utils.gaussian_aff_fn, sigma=sigma2)
    return pygm.utils.build_aff_mat(None, e1, c1, None, e2, c2, np.array([g1.n_nodes]), None,
                                    np.array([g2.n_nodes]), None, edge_aff_fn=fn)


def _pygm_assignment(X):
    X = pygm.hungarian(X)
    return np.where(X.max(axis=1) > 0, np.argmax(X, axis=1), -1)


@pytest.fixture
def rng():
    return np.random.default_rng(11)


@pytest.mark.parametrize("sigma2", [0.05, 0.15])
def test_affinity_matches_build_aff_mat(sigma2, rng):
    g1 = Graph.from_points(rng.random((5, 2)), edges="full")
    g2 = Graph.from_points(rng.random((7, 2)), edges="full")
    K_pg = _pygm_K(g1, g2, sigma2)
    dense = gaussian_edge_affinity(g1, g2, sigma2=sigma2, backend="dense").to_dense()
    np.testing.assert_allclose(dense, K_pg, rtol=0, atol=1e-12)
    sep = gaussian_edge_affinity(g1, g2, sigma2=sigma2, backend="separable")
    assert np.abs(sep.to_dense() - K_pg).max() <= sep.max_error


@pytest.mark.parametrize("deformation", [0.0, 0.05])
def test_sm_identical_to_pygmtools(deformation, rng):
    for _ in range(2):
        g1, g2, _ = _problem(rng, 9, deformation)
        K = _pygm_K(g1, g2, 0.15)
        X_pg = pygm.sm(K, 9, 9, max_iter=50)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", ConvergenceWarning)
            res = sm(K, n1=9, n2=9, max_iter=50)
        np.testing.assert_allclose(res.soft, X_pg, atol=1e-10)
        np.testing.assert_array_equal(res.assignment, _pygm_assignment(X_pg))


def _outlier_problem(rng, n_in, out1, out2, deformation=0.03):
    P = rng.random((n_in, 2))
    Q = P + deformation * rng.standard_normal(P.shape)
    P1 = np.vstack([P, rng.random((out1, 2))])
    Q2 = np.vstack([Q, rng.random((out2, 2))])[rng.permutation(n_in + out2)]
    return Graph.from_points(P1, edges="full"), Graph.from_points(Q2, edges="full")


@pytest.mark.parametrize("out1,out2", [(0, 0), (4, 4), (0, 5), (5, 0)])
def test_rrwm_pygmtools_variant_reproduces_pygmtools(out1, out2, rng):
    for _ in range(2):
        g1, g2 = _outlier_problem(rng, 10, out1, out2)
        n1, n2 = g1.n_nodes, g2.n_nodes
        K = _pygm_K(g1, g2, 0.15)
        X_pg = pygm.rrwm(K, n1, n2)
        a_pg = _pygm_assignment(X_pg)
        # pygmtools' loop for its full 50 iterations: the same mixture, entrywise
        with pytest.warns(ConvergenceWarning, match="rrwm"):
            full = rrwm(K, n1=n1, n2=n2, variant="pygmtools", tol=1e-300, max_iter=50)
        np.testing.assert_allclose(full.info["scores"], X_pg, rtol=0, atol=1e-10)
        # defaults (stops once the mixture settles): the same assignment, through K or the
        # factorized affinity
        for aff in (K, gaussian_edge_affinity(g1, g2, sigma2=0.15)):
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", ConvergenceWarning)
                res = rrwm(aff, n1=n1, n2=n2, variant="pygmtools") if aff is K else \
                    rrwm(aff, variant="pygmtools")
            np.testing.assert_array_equal(res.assignment, a_pg)
            assert res.info["variant"] == "pygmtools" and res.n_iter <= 50


def test_rrwm_and_ipfp_agree_on_easy_problems(rng):
    for deformation in (0.0, 0.01):
        g1, g2, truth = _problem(rng, 10, deformation)
        K = _pygm_K(g1, g2, 0.15)
        a_rrwm = _pygm_assignment(pygm.rrwm(K, 10, 10))
        res = rrwm(K, n1=10, n2=10)
        np.testing.assert_array_equal(res.assignment, a_rrwm)
        np.testing.assert_array_equal(res.assignment, truth)
        with np.errstate(divide="ignore", invalid="ignore"):   # pygmtools divides 0 / 0
            a_ipfp = _pygm_assignment(pygm.ipfp(K, 10, 10))
        res = ipfp(K, n1=10, n2=10, init="sm")
        np.testing.assert_array_equal(a_ipfp, truth)
        np.testing.assert_array_equal(res.assignment, truth)
        X = np.zeros((10, 10))
        X[np.arange(10), a_ipfp] = 1
        x = X.ravel(order="F")
        assert res.objective >= x @ K @ x - 1e-9
