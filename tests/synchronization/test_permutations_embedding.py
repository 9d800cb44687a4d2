"""``synchronize_permutations(..., keep_embedding=True)``: the relaxed solution in ``info``.

Issue #12 (transitive assignment kernels) needs the relaxed ``Q_i`` of the orthogonal method
(kernel variant "relaxed", ALGORITHMS.md §2.2 step 6c).
"""

import numpy as np
import pytest

from transync.datasets import make_permutation_collection
from transync.permutations import assignment_to_matrix
from transync.synchronization import synchronize_permutations


@pytest.mark.parametrize("method", ["orthogonal", "spectral", "matcheig"])
def test_default_keeps_no_embedding(method):
    data = make_permutation_collection(5, 4, corruption=0.0, rng=0)
    res = synchronize_permutations(data.pairwise, method=method)
    assert "embedding" not in res.info


def test_orthogonal_embedding_is_orthogonal_and_consistent_at_zero_noise():
    N, n = 7, 5
    data = make_permutation_collection(N, n, corruption=0.0, rng=1)
    res = synchronize_permutations(data.pairwise, method="orthogonal", keep_embedding=True)
    Q = res.info["embedding"]
    assert Q.shape == (N * n, n)
    Q = Q.reshape(N, n, n)
    np.testing.assert_allclose(Q @ Q.transpose(0, 2, 1), np.broadcast_to(np.eye(n), (N, n, n)),
                               atol=1e-8)
    for i, j in [(0, 1), (2, 6), (5, 3)]:
        P = assignment_to_matrix(data.true_pairwise(i, j), n)
        np.testing.assert_allclose(Q[i] @ Q[j].T, P, atol=1e-6)


def test_spectral_embedding_spans_the_consistent_maps():
    N, n = 6, 4
    data = make_permutation_collection(N, n, corruption=0.0, rng=2)
    res = synchronize_permutations(data.pairwise, method="spectral", keep_embedding=True)
    U = res.info["embedding"].reshape(N, n, n)
    for i, j in [(0, 5), (1, 2)]:
        # normalized block matrix D^-1/2 T D^-1/2 = T / N: U U^T = T / N at zero noise
        np.testing.assert_allclose(N * U[i] @ U[j].T,
                                   assignment_to_matrix(data.true_pairwise(i, j), n), atol=1e-8)


def test_embedding_rows_follow_objects_and_components():
    # two components {0, 1} and {2, 3} plus a lone object 4 (sizes given)
    a = np.array([1, 0, 2])
    pairwise = {(0, 1): a, (2, 3): a}
    res = synchronize_permutations(pairwise, method="orthogonal", sizes=[3, 3, 3, 3, 2],
                                   keep_embedding=True)
    E = res.info["embedding"]
    assert E.shape == (14, res.n_universe) == (14, 8)
    # component blocks occupy their own columns
    assert not E[:6, 3:].any() and not E[6:12, :3].any() and not E[6:12, 6:].any()
    np.testing.assert_array_equal(E[12:], np.eye(8)[res.labels[4]])
    np.testing.assert_allclose(E[:3] @ E[3:6].T, assignment_to_matrix(a, 3), atol=1e-8)


def test_keep_embedding_must_be_bool():
    data = make_permutation_collection(3, 3, corruption=0.0, rng=0)
    with pytest.raises(TypeError, match="keep_embedding"):
        synchronize_permutations(data.pairwise, keep_embedding="yes")
