"""Tests for synchronize_linear_maps / synchronize_homographies (Bernard null-space method)."""

import numpy as np
import pytest

from transync.datasets import make_noisy_homographies, make_noisy_linear_maps
from transync.exceptions import DegenerateInputError
from transync.homography import corner_error
from transync.synchronization import (
    LinearMapSyncResult,
    synchronize_homographies,
    synchronize_linear_maps,
)


@pytest.mark.parametrize("group", ["GL", "SL", "SO"])
@pytest.mark.parametrize("density", [1.0, 0.4])
def test_exact_on_consistent_input(group, density):
    prob = make_noisy_linear_maps(9, 3, group=group, noise=0.0, density=density, rng=3)
    res = synchronize_linear_maps(prob.observed, mask=prob.mask, group=group)
    assert isinstance(res, LinearMapSyncResult)
    np.testing.assert_allclose(res.maps, prob.truth, atol=1e-9)
    # pairwise(i, j) reproduces the observation, also for unobserved pairs (truth)
    truth_pw = prob.true_pairwise()
    for i, j in [(1, 2), (3, 0), (8, 5)]:
        np.testing.assert_allclose(res.pairwise(i, j), truth_pw[i, j], atol=1e-9)
    full = res.to_array()
    np.testing.assert_allclose(full[prob.mask], prob.observed[prob.mask], atol=1e-9)


def test_convention_planted_maps():
    """T[i, j] = M_i^-1 M_j with maps[i] = object i into the reference."""
    rng = np.random.default_rng(0)
    M = rng.normal(size=(5, 2, 2)) + 2 * np.eye(2)
    M = np.linalg.solve(M[0], M)  # gauge: M_0 = I
    T = np.einsum("iab,jbc->ijac", np.linalg.inv(M), M)
    res = synchronize_linear_maps(T, reference=0)
    np.testing.assert_allclose(res.maps, M, atol=1e-10)
    # another reference: maps[i] = M_r^-1 M_i
    res3 = synchronize_linear_maps(T, reference=3)
    np.testing.assert_allclose(res3.maps, np.linalg.solve(M[3], M), atol=1e-10)
    np.testing.assert_allclose(res3.pairwise(1, 4), T[1, 4], atol=1e-10)


def test_dict_input_and_one_direction_only():
    prob = make_noisy_linear_maps(5, 3, group="GL", noise=0.0, rng=1)
    pairs = {(i, j): prob.observed[i, j] for i in range(5) for j in range(5) if i < j}
    res = synchronize_linear_maps(pairs)
    np.testing.assert_allclose(res.maps, prob.truth, atol=1e-9)
    assert res.mask.all() == False  # noqa: E712  (diagonal stays False)
    assert res.mask[4, 0] and res.mask[0, 4]


def test_cycle_consistency_of_output():
    prob = make_noisy_linear_maps(7, 3, group="GL", noise=0.1, rng=2)
    res = synchronize_linear_maps(prob.observed, mask=prob.mask)
    A = res.to_array()
    np.testing.assert_allclose(A[1, 2] @ A[2, 5], A[1, 5], atol=1e-9)


def test_weights_favour_good_pairs():
    prob = make_noisy_linear_maps(8, 3, group="SO", noise=0.01, outlier_fraction=0.1, rng=4)
    w = np.where(prob.outliers, 1e-6, 1.0)
    res_w = synchronize_linear_maps(prob.observed, mask=prob.mask, weights=w, group="SO")
    res = synchronize_linear_maps(prob.observed, mask=prob.mask, group="SO")
    err_w = np.abs(res_w.maps - prob.truth).max()
    err = np.abs(res.maps - prob.truth).max()
    assert err_w < 0.05 < err


def test_dict_weights_equal_the_array_they_spell():
    """A dict of weights, the same form as a dict of maps, reads like the (N, N) array: either
    direction of a pair names it; an observed pair without an entry is refused by name."""
    prob = make_noisy_linear_maps(6, 3, group="GL", noise=0.05, rng=1)
    rng = np.random.default_rng(0)
    w = rng.uniform(0.1, 2.0, (6, 6))
    w = np.triu(w, 1) + np.triu(w, 1).T
    as_dict = {(i, j): float(w[i, j]) for i in range(6) for j in range(i + 1, 6)}
    a = synchronize_linear_maps(prob.observed, weights=w)
    b = synchronize_linear_maps(prob.observed, weights=as_dict)
    np.testing.assert_allclose(b.maps, a.maps, atol=1e-12)
    assert not np.allclose(a.maps, synchronize_linear_maps(prob.observed).maps, atol=1e-6)
    with pytest.raises(ValueError, match=r"`weights` key \(0, 6\) names object 6, but the input "
                                         r"has 6 objects"):
        synchronize_linear_maps(prob.observed, weights={**as_dict, (0, 6): 1.0})
    del as_dict[(2, 4)]
    with pytest.raises(ValueError, match=r"`weights` has no entry for pair \(2, 4\)"):
        synchronize_linear_maps(prob.observed, weights=as_dict)


@pytest.mark.parametrize("group", ["GL", "SL", "SO"])
def test_robust_rejects_outliers(group):
    prob = make_noisy_linear_maps(20, 3, group=group, noise=0.02, outlier_fraction=0.2,
                                  density=0.7, rng=0)
    plain = synchronize_linear_maps(prob.observed, mask=prob.mask, group=group)
    res = synchronize_linear_maps(prob.observed, mask=prob.mask, group=group, robust=True)
    assert res.converged
    assert np.abs(res.maps - prob.truth).max() < 0.1
    assert np.abs(plain.maps - prob.truth).max() > 0.2
    rejected = res.mask & ~res.inliers
    np.testing.assert_array_equal(rejected[prob.mask], prob.outliers[prob.mask])


def test_so_output_is_rotation():
    prob = make_noisy_linear_maps(6, 3, group="SO", noise=0.1, rng=5)
    res = synchronize_linear_maps(prob.observed, mask=prob.mask, group="SO")
    np.testing.assert_allclose(res.maps @ res.maps.transpose(0, 2, 1),
                               np.broadcast_to(np.eye(3), (6, 3, 3)), atol=1e-10)
    np.testing.assert_allclose(np.linalg.det(res.maps), 1.0, atol=1e-10)


def test_so2_rotation_averaging():
    prob = make_noisy_linear_maps(6, 2, group="SO", noise=0.0, rng=6)
    res = synchronize_linear_maps(prob.observed, mask=prob.mask, group="SO")
    np.testing.assert_allclose(res.maps, prob.truth, atol=1e-10)


def test_homographies_exact_and_det_one():
    prob = make_noisy_homographies(8, noise=0.0, density=0.5, rng=0)
    res = synchronize_homographies(prob.observed, mask=prob.mask, image_size=prob.image_size)
    err = corner_error(res.maps, prob.truth, image_size=prob.image_size)
    assert err.max() < 1e-6
    np.testing.assert_allclose(np.linalg.det(res.maps), 1.0, atol=1e-9)
    Hp = res.pairwise(2, 5)
    Ht = prob.true_pairwise()[2, 5]
    np.testing.assert_allclose(Hp / Hp[2, 2], Ht / Ht[2, 2], rtol=1e-6, atol=1e-9)


def test_homographies_robust_target_20_percent_outliers():
    """SL(3), 640x480, 0.5 px pairwise noise, 20 % outlier pairs: every view < 0.5 px."""
    prob = make_noisy_homographies(20, noise=0.5, outlier_fraction=0.2, rng=1)
    res = synchronize_homographies(prob.observed, mask=prob.mask, image_size=prob.image_size,
                                   robust=True)
    err = corner_error(res.maps, prob.truth, image_size=prob.image_size)
    assert err.max() < 0.5
    plain = synchronize_homographies(prob.observed, mask=prob.mask, image_size=prob.image_size)
    assert corner_error(plain.maps, prob.truth, image_size=prob.image_size).mean() > 2.0
    # residuals are in pixels: inliers near the noise level, outliers large
    assert np.nanmedian(res.residuals[prob.mask & ~prob.outliers]) < 1.0
    assert np.nanmin(res.residuals[prob.outliers]) > 10.0


def test_homographies_without_normalization_is_worse_conditioned():
    prob = make_noisy_homographies(10, noise=0.5, rng=2)
    res = synchronize_homographies(prob.observed, mask=prob.mask, image_size=prob.image_size)
    err = corner_error(res.maps, prob.truth, image_size=prob.image_size)
    assert err.max() < 0.6


def test_disconnected_graph_raises_or_components():
    prob = make_noisy_linear_maps(6, 3, noise=0.0, rng=0)
    mask = np.zeros((6, 6), dtype=bool)
    for i, j in [(0, 1), (1, 2), (3, 4), (4, 5)]:
        mask[i, j] = mask[j, i] = True
    with pytest.raises(DegenerateInputError, match="disconnected: 2 components"):
        synchronize_linear_maps(prob.observed, mask=mask)
    with pytest.raises(ValueError, match="disconnected"):
        synchronize_linear_maps(prob.observed, mask=mask)
    res = synchronize_linear_maps(prob.observed, mask=mask, disconnected="component")
    np.testing.assert_array_equal(res.info["excluded"], [3, 4, 5])
    assert np.isnan(res.maps[3:]).all()
    np.testing.assert_allclose(res.maps[:3], prob.truth[:3], atol=1e-9)


def test_bad_input():
    prob = make_noisy_linear_maps(4, 3, noise=0.0, rng=0)
    T = prob.observed.copy()
    with pytest.raises(ValueError, match=r"shape \(N, N, d, d\)"):
        synchronize_linear_maps(T[:, :3])
    with pytest.raises(ValueError, match="must have 4 dimensions"):
        synchronize_linear_maps(T[0])
    with pytest.raises(ValueError, match=r"`mask` must have shape \(4, 4\)"):
        synchronize_linear_maps(T, mask=np.ones((3, 3), dtype=bool))
    # one meaning of `mask` everywhere: the diagonal is ignored (self-pairs carry nothing)
    full = synchronize_linear_maps(T, mask=np.ones((4, 4), dtype=bool))
    np.testing.assert_allclose(full.maps, synchronize_linear_maps(T).maps, atol=1e-12)
    with pytest.raises(ValueError, match="self-pairs"):
        synchronize_linear_maps({(0, 0): np.eye(3), (0, 1): np.eye(3)})
    Ts = T.copy()
    Ts[1, 2] = np.array([[1.0, 2, 3], [2, 4, 6], [0, 0, 1]])
    with pytest.raises(ValueError, match=r"`T\[1, 2\]` must be invertible"):
        synchronize_linear_maps(Ts)
    Tn = T.copy()
    Tn[0, 3, 0, 0] = np.nan
    with pytest.raises(ValueError, match="finite"):
        synchronize_linear_maps(Tn)
    with pytest.raises(ValueError, match="`weights` must have shape"):
        synchronize_linear_maps(T, weights=np.ones((3, 3)))
    with pytest.raises(ValueError, match="non-negative"):
        synchronize_linear_maps(T, weights=-np.ones((4, 4)))
    with pytest.raises(ValueError, match="`group` must be one of"):
        synchronize_linear_maps(T, group="SE")
    with pytest.raises(ValueError, match="`reference` must be <= 3"):
        synchronize_linear_maps(T, reference=4)
    with pytest.raises(ValueError, match=r"`d` = 4|d = 4"):
        synchronize_linear_maps(np.broadcast_to(np.eye(4), (3, 3, 4, 4)), group="SO")
    with pytest.raises(ValueError, match="image_size"):
        synchronize_homographies(T, image_size=(640,))


def test_triples_are_accepted_like_dicts():
    """Pairwise maps as a list of (i, j, map) triples, as the other synchronizers accept."""
    from transync.synchronization import synchronize_homographies

    A = np.array([[1.0, 0.1, 2.0], [0.0, 1.0, 1.0], [0.0, 0.0, 1.0]])
    triples = [(0, 1, A), (1, 2, np.eye(3)), (0, 2, A)]
    as_dict = {(i, j): M for i, j, M in triples}
    for fn in (synchronize_linear_maps, synchronize_homographies):
        np.testing.assert_allclose(fn(triples).maps, fn(as_dict).maps, atol=1e-12)
    with pytest.raises(ValueError, match=r"`H\[1\]` repeats the pair \(0, 1\)"):
        synchronize_homographies([(0, 1, A), (0, 1, A)])
    with pytest.raises(TypeError, match="`H` keys must be pairs"):
        synchronize_homographies({0: np.eye(3)})


def test_so_pairwise_maps_do_not_depend_on_the_reference():
    """group="SO" projected the gauge-fixed maps to rotations one by one; the projection does
    not commute with the gauge, so under noise the pairwise maps changed with `reference` (by
    up to 1.5e-3 at noise 0.05; metamorphic test). The null-space blocks are projected first
    now: the reference only rotates every map by one rotation, as for GL and SL."""
    rng = np.random.default_rng(2)
    N = 5
    R = np.array([np.linalg.qr(rng.normal(size=(3, 3)))[0] for _ in range(N)])
    R *= np.sign(np.linalg.det(R))[:, None, None]
    T = np.einsum("iba,jbc->ijac", R, R) + 0.05 * rng.normal(size=(N, N, 3, 3))
    A = [synchronize_linear_maps(T, group="SO", reference=r).to_array() for r in range(N)]
    for r in range(1, N):
        np.testing.assert_allclose(A[r], A[0], atol=1e-12)
    rot = synchronize_linear_maps(T, group="SO", reference=3).maps
    np.testing.assert_allclose(np.linalg.det(rot), 1.0)
    np.testing.assert_allclose(np.einsum("iab,icb->iac", rot, rot),
                               np.broadcast_to(np.eye(3), (N, 3, 3)), atol=1e-12)


def test_homography_residuals_are_pixels_of_each_view_with_mixed_sizes():
    # a pair's corner residual lives in its first view; one mean scale for all views reported
    # 2x the pixels of a 320 x 240 view and 0.5x those of a 1280 x 960 one beside it
    from transync.geometry import normalization_matrix, transfer_points

    rng = np.random.default_rng(0)
    sizes = np.array([[320, 240], [320, 240], [1280, 960]])
    Nm = np.stack([normalization_matrix(s) for s in sizes])
    G = [np.eye(3)] + [np.eye(3) + 0.05 * rng.normal(size=(3, 3)) for _ in range(2)]
    Tn = np.array([[np.linalg.inv(G[i]) @ G[j] for j in range(3)] for i in range(3)])
    Tn[0, 1] = Tn[0, 1] @ (np.eye(3) + 1e-3 * rng.normal(size=(3, 3)))
    Tn[1, 0] = np.linalg.inv(Tn[0, 1])
    H = np.einsum("iab,ijbc,jcd->ijad", np.linalg.inv(Nm), Tn, Nm)
    res = synchronize_homographies(H, image_size=sizes)
    square = np.array([[-1, -1], [1, -1], [1, 1], [-1, 1.0]])
    for i, j in [(0, 1), (1, 0), (0, 2), (2, 0), (1, 2)]:
        est = np.linalg.solve(res.maps[i], res.maps[j])
        corners = transfer_points(np.linalg.inv(Nm[j]), square)
        pixels = np.linalg.norm(transfer_points(H[i, j], corners)
                                - transfer_points(est, corners), axis=1).mean()
        np.testing.assert_allclose(res.residuals[i, j], pixels, rtol=1e-9)


def test_per_object_residual_scale_is_checked():
    data = make_noisy_linear_maps(4, noise=0.01, rng=0)
    res1 = synchronize_linear_maps(data.observed, mask=data.mask)
    res2 = synchronize_linear_maps(data.observed, mask=data.mask,
                                   residual_scale=np.array([1.0, 2.0, 3.0, 4.0]))
    ok = np.isfinite(res1.residuals)
    np.testing.assert_allclose(res2.residuals[ok],
                               (res1.residuals * np.arange(1, 5)[:, None])[ok])
    with pytest.raises(ValueError, match="one factor per object"):
        synchronize_linear_maps(data.observed, mask=data.mask, residual_scale=np.ones(3))
    with pytest.raises(ValueError, match="must be positive"):
        synchronize_linear_maps(data.observed, mask=data.mask, residual_scale=np.zeros(4))


def test_homography_messages_name_H_not_the_internal_T():
    """synchronize_homographies validated through synchronize_linear_maps, whose messages
    named its own argument `T`."""
    from transync.synchronization import synchronize_homographies

    H = np.broadcast_to(np.eye(3), (3, 3, 3, 3)).copy()
    H[0, 1] = 0
    with pytest.raises(ValueError, match=r"`H\[0, 1\]` must be invertible"):
        synchronize_homographies(H)
    H = np.broadcast_to(np.eye(3), (3, 3, 3, 3)).copy()
    H[1, 2, 0, 0] = np.nan
    with pytest.raises(ValueError, match=r"`H\[1, 2\]` must be finite where observed"):
        synchronize_homographies(H)
    with pytest.raises(ValueError, match=r"`H\[\(0, 1\)\]` must have shape \(3, 3\)"):
        synchronize_homographies({(0, 1): np.eye(2)})               # was "residual='corner'"
    with pytest.raises(ValueError, match=r"`image_size` must lie in \[1e-06, 1e\+09\]"):
        synchronize_homographies(np.broadcast_to(np.eye(3), (3, 3, 3, 3)),
                                 image_size=(1e300, 1e300))        # was "H[0, 1] singular"


def test_inconsistent_tiny_blocks_are_degenerate_not_linalg_errors():
    """A singular null-space block gave np.linalg's LinAlgError: now DegenerateInputError."""
    for seed in range(5):
        T = np.random.default_rng(seed).normal(size=(3, 3, 2, 2)) * 1e-20
        with pytest.raises(DegenerateInputError, match="null.space"):
            synchronize_linear_maps(T)


@pytest.mark.parametrize("group", ["GL", "SL"])
def test_singular_non_reference_block_names_the_object(group):
    """The non-reference case on a built null-space basis (which of the two cases random
    tiny blocks reach depends on the LAPACK build: numpy 2.4's SVD reached only the
    reference's one on the seeds that once reached both)."""
    from transync.synchronization._linear_maps import _maps_from_nullspace

    U = np.stack([np.eye(2), np.eye(2), np.array([[1.0, 1.0], [1.0, 1.0]])])
    with pytest.raises(DegenerateInputError, match="null-space block of object 2"):
        _maps_from_nullspace(U, 0, group)
    with pytest.raises(DegenerateInputError, match="reference block of the null space"):
        _maps_from_nullspace(U, 2, group)
    np.testing.assert_allclose(_maps_from_nullspace(U[:2], 0, group), np.stack([np.eye(2)] * 2))


def test_objective_finite_with_huge_weights():
    """weights ~1e250 times squared residuals overflowed: an inf objective from finite
    residuals. Only the weights' ratios matter."""
    p = make_noisy_linear_maps(4, dim=2, noise=0, outlier_fraction=0.3, rng=972)
    a = synchronize_linear_maps(p.observed * 1e40, weights=np.full((4, 4), 1e250))
    b = synchronize_linear_maps(p.observed * 1e40, weights=np.full((4, 4), 1.0))
    assert np.isfinite(a.objective)
    assert a.objective == pytest.approx(b.objective, rel=1e-9)


def test_n_objects_must_match_an_array():
    T = make_noisy_linear_maps(4, noise=0.0, rng=0).observed
    with pytest.raises(ValueError, match=r"`n_objects` must match the 4 objects"):
        synchronize_linear_maps(T, n_objects=7)
    assert synchronize_linear_maps(T, n_objects=4).maps.shape == (4, 3, 3)
