"""Geometric verification of pairwise assignments (`verify_assignment`) and its stage in
`match_collection` (`verify=`): planted transforms recovered exactly, spurious matches dropped,
missed ones recovered, failures reported, relabelling invariance, the input contract."""

import functools
import pickle

import numpy as np
import pytest

from transync import match_collection
from transync.datasets import make_subgraph_collection
from transync.graphs import Graph
from transync.matching import (
    VERIFY_MODELS,
    VerificationResult,
    gaussian_edge_affinity,
    verify_assignment,
)
from transync.metrics import multimatching_precision_recall
from transync.permutations import MultiMatching


def _transform(model, rng):
    a = rng.uniform(-0.6, 0.6)
    s = rng.uniform(0.7, 1.4)
    R = s * np.array([[np.cos(a), -np.sin(a)], [np.sin(a), np.cos(a)]])
    H = np.eye(3)
    H[:2, :2] = R
    H[:2, 2] = rng.uniform(-3, 3, 2)
    if model in ("affine", "homography"):
        H[:2, :2] = R @ np.array([[1.0, rng.uniform(-0.3, 0.3)], [0.0, rng.uniform(0.8, 1.2)]])
    if model == "homography":
        H[2, :2] = rng.uniform(-0.15, 0.15, 2)
    return H


def _apply(H, p):
    q = p @ H[:2, :2].T + H[:2, 2]
    return q / (p @ H[2, :2] + H[2, 2])[:, None]


def _planted(model, seed, n=20, shared=15, outliers=3, corrupt=4):
    """Graph 1: n points; graph 2: the first `shared` mapped by a transform, plus outliers,
    shuffled. A putative map with `corrupt` wrong matches, two true matches missing, and the
    unshared nodes matched to outliers."""
    rng = np.random.default_rng(seed)
    p1 = rng.random((n, 2))
    H = _transform(model, rng)
    q = np.vstack([_apply(H, p1[:shared]), _apply(H, rng.random((outliers, 2)) + 1.5)])
    perm = rng.permutation(len(q))
    p2 = q[perm]
    pos = np.empty_like(perm)
    pos[perm] = np.arange(len(q))                   # where row k of q went
    truth = np.full(n, -1)
    truth[:shared] = pos[:shared]
    putative = truth.copy()
    wrong = rng.choice(shared, corrupt, replace=False)
    putative[wrong] = putative[np.roll(wrong, 1)]   # a cycle of wrong matches
    putative[shared - 2:shared] = -1 if corrupt < shared - 2 else putative[shared - 2:shared]
    putative[shared:shared + outliers] = pos[shared:shared + outliers]   # unshared -> outliers
    return p1, p2, putative, truth, H


@pytest.mark.parametrize("model", sorted(VERIFY_MODELS))
@pytest.mark.parametrize("seed", range(4))
def test_planted_transform_is_recovered_exactly(model, seed):
    """Zero noise: the verified map is the truth (wrong matches dropped or corrected, missed
    ones recovered, unshared nodes unmatched) and the transform is the planted one."""
    p1, p2, putative, truth, H = _planted(model, seed)
    res = verify_assignment(p1, p2, putative, model=model, rng=seed)
    assert isinstance(res, VerificationResult) and res.verified and res.model == model
    np.testing.assert_array_equal(res.assignment, truth)
    assert res.n_inliers == int(np.sum(truth >= 0))
    np.testing.assert_allclose(res.transform / res.transform[2, 2], H / H[2, 2], atol=1e-6)
    assert res.threshold > 0 and 1 <= res.n_rounds <= 5


def _perspective_views(seed, n=24):
    """Points of one plane seen by two pinhole cameras with strong foreshortening: one
    homography explains every match, no affine map does within the gate."""
    rng = np.random.default_rng(seed)
    p1 = rng.random((n, 2))
    H = np.array([[1.0, 0.1, 0.2], [0.05, 0.9, 0.1], [0.9, 0.6, 1.0]])
    return p1, _apply(H, p1)


@pytest.mark.parametrize("seed", range(3))
def test_candidate_models_keep_the_best_supported(seed):
    """model=(a, b): each candidate is the single-model verification from the same rng
    state; the verified one with more matches is kept (ties: the earlier), and `support`
    records every candidate's matches."""
    p1, p2 = _perspective_views(seed)
    putative = np.arange(len(p1))
    putative[[0, 1, 2]] = putative[[1, 2, 0]]
    both = verify_assignment(p1, p2, putative, model=("affine", "homography"), rng=seed)
    alone = {m: verify_assignment(p1, p2, putative, model=m, rng=seed)
             for m in ("affine", "homography")}
    assert both.support == {m: r.n_inliers for m, r in alone.items()}
    assert alone["homography"].n_inliers == len(p1) > alone["affine"].n_inliers
    assert both.model == "homography" and both.verified
    np.testing.assert_array_equal(both.assignment, np.arange(len(p1)))
    np.testing.assert_array_equal(both.transform, alone["homography"].transform)
    # the order decides ties only: both orders keep the homography here
    assert verify_assignment(p1, p2, putative, model=("homography", "affine"),
                             rng=seed).model == "homography"
    # an affine scene: both explain every match, the earlier model is kept
    A = np.array([[0.9, -0.3], [0.4, 1.1]])
    tie = verify_assignment(p1, p1 @ A.T + 1, putative, model=("affine", "homography"),
                            rng=seed)
    assert tie.model == "affine" and tie.support == {"affine": 24, "homography": 24}
    assert verify_assignment(p1, p1 @ A.T + 1, putative, model=("homography", "affine"),
                             rng=seed).model == "homography"
    # one model asked for: its own support only
    assert alone["affine"].support == {"affine": alone["affine"].n_inliers}


def test_candidate_models_share_the_generator_state_of_the_first():
    """With a Generator: every candidate starts from its state, which is then left where the
    first model's own call leaves it; on random putative matches (RANSAC's order matters)
    the first candidate's verdict is the single model's, pair after pair."""
    rng = np.random.default_rng(4)
    for _ in range(30):
        p1, p2 = rng.random((16, 2)), rng.random((14, 2))
        p2[:8] = p1[:8] * 1.1 + 0.2 + 0.02 * rng.standard_normal((8, 2))
        putative = np.full(16, -1)
        putative[:8] = np.arange(8)
        putative[:3] = rng.permutation(3)
        putative[8:14] = 8 + rng.permutation(6)
        g1, g2 = np.random.default_rng(7), np.random.default_rng(7)
        both = verify_assignment(p1, p2, putative, model=("affine", "homography"), rng=g1)
        first = verify_assignment(p1, p2, putative, model="affine", rng=g2)
        assert both.support["affine"] == first.n_inliers
        assert g1.bit_generator.state == g2.bit_generator.state


def test_candidate_models_that_all_fail_return_the_first_failure():
    rng = np.random.default_rng(0)
    p1, p2 = rng.random((15, 2)), rng.random((15, 2))
    res = verify_assignment(p1, p2, rng.permutation(15), model=("similarity", "affine"), rng=0)
    assert not res.verified and res.model == "similarity" and np.all(res.assignment == -1)
    assert res.support == {"similarity": 0, "affine": 0}


@pytest.mark.parametrize("model, exc, match", [
    ((), TypeError, "non-empty sequence"),
    (("affine", "affine"), ValueError, "twice"),
    (("affine", "projective"), ValueError, "or a sequence of distinct ones"),
    (("affine", 3), ValueError, "or a sequence of distinct ones"),
    (3, TypeError, "`model` must be one of .* non-empty sequence"),
    ("projective", ValueError, "`model` must be one of"),
])
def test_candidate_models_input_contract(model, exc, match):
    p1, p2 = _perspective_views(0)
    with pytest.raises(exc, match=match):
        verify_assignment(p1, p2, np.arange(len(p1)), model=model)
    # min_inliers must allow every candidate's minimal sample
    with pytest.raises(ValueError, match="min_inliers"):
        verify_assignment(p1, p2, np.arange(len(p1)), model=("affine", "homography"),
                          min_inliers=3)


def test_relabelling_the_second_graph_relabels_the_answer():
    p1, p2, putative, truth, _ = _planted("affine", 7)
    perm = np.random.default_rng(1).permutation(len(p2))      # new node u is old perm[u]
    inv = np.argsort(perm)
    moved = np.where(putative >= 0, inv[np.maximum(putative, 0)], -1)
    a = verify_assignment(p1, p2, putative, rng=3).assignment
    b = verify_assignment(p1, p2[perm], moved, rng=3).assignment
    np.testing.assert_array_equal(b, np.where(a >= 0, inv[np.maximum(a, 0)], -1))


def test_same_rng_same_answer_and_scale_free_gate():
    p1, p2, putative, truth, _ = _planted("affine", 3)
    r1 = verify_assignment(p1, p2, putative, rng=5)
    r2 = verify_assignment(p1, p2, putative, rng=5)
    np.testing.assert_array_equal(r1.assignment, r2.assignment)
    # pixels instead of unit coordinates: the gate follows the points' spacing
    r3 = verify_assignment(640 * p1, 480 * p2 + 1e4, putative, rng=5)
    np.testing.assert_array_equal(r3.assignment, truth)
    assert r3.threshold == pytest.approx(480 * r1.threshold, rel=1e-9)


def test_unexplained_matches_fail_with_an_empty_map():
    """Random putative matches between unrelated point sets: no transform explains half of
    them (the default min_inliers) within half the point spacing, so nothing survives."""
    rng = np.random.default_rng(0)
    failures = 0
    for _ in range(20):
        p1, p2 = rng.random((15, 2)), rng.random((15, 2))
        res = verify_assignment(p1, p2, rng.permutation(15), rng=0)
        if not res.verified:
            failures += 1
            assert np.all(res.assignment == -1) and res.n_inliers == 0
    assert failures >= 18
    # too few putative matches for the model's sample: failed, transform NaN
    res = verify_assignment(rng.random((5, 2)), rng.random((5, 2)), [0, 1, -1, -1, -1])
    assert not res.verified and np.all(res.assignment == -1)
    assert np.all(np.isnan(res.transform)) and res.n_rounds == 0
    # one point on the other side: no spacing to gate by, nothing to verify
    assert not verify_assignment([[0.0, 0.0]], [[1.0, 1.0]], [0]).verified


def test_min_inliers_decides_what_verifies():
    p1, p2, putative, truth, _ = _planted("affine", 2)
    assert verify_assignment(p1, p2, putative, min_inliers=15, rng=0).verified
    res = verify_assignment(p1, p2, putative, min_inliers=16, rng=0)
    assert not res.verified and np.all(res.assignment == -1)


@pytest.mark.parametrize("kwargs, exc, match", [
    (dict(points1=np.zeros((3, 3))), ValueError, "points1.*shape \\(n, 2\\)"),
    (dict(points2=np.zeros((0, 2))), ValueError, "points2.*at least one point"),
    (dict(points1=[[np.nan, 0.0]] * 4), ValueError, "points1"),
    (dict(points2=np.full((4, 2), 1e13)), ValueError, "points2.*1e\\+12"),
    (dict(assignment=[0, 1, 2]), ValueError, "assignment.*length 4"),
    (dict(assignment=[0, 1, 2, 4]), ValueError, "assignment.*< n2=4"),
    (dict(assignment=[0, 0, 1, 2]), ValueError, "assignment.*injective"),
    (dict(assignment=[0.5, 1, 2, 3]), TypeError, "assignment"),
    (dict(model="projective"), ValueError, "model"),
    (dict(threshold=0.0), ValueError, "threshold"),
    (dict(threshold=np.inf), ValueError, "threshold"),
    (dict(min_inliers=2), ValueError, "min_inliers.*>= 3"),
    (dict(min_inliers=4.0), TypeError, "min_inliers"),
    (dict(max_rounds=0), ValueError, "max_rounds"),
    (dict(rng=-1), ValueError, "rng"),
])
def test_bad_input_is_named(kwargs, exc, match):
    args = dict(points1=np.random.default_rng(0).random((4, 2)),
                points2=np.random.default_rng(1).random((4, 2)), assignment=[0, 1, 2, 3])
    args.update(kwargs)
    with pytest.raises(exc, match=match):
        verify_assignment(**args)


# ------------------------------------------------------------------ match_collection(verify=)

def _landmark_collection(n_graphs=8, n_points=24, keep=(14, 20), seed=0):
    """Views of one planar point set under mild affine maps (a rotation, a translation, a
    little shear: edge lengths change a little, as between frames of a sequence), each keeping
    a random subset, nodes shuffled, Delaunay graphs; ground truth as universe labels."""
    rng = np.random.default_rng(seed)
    base = rng.random((n_points, 2))
    graphs, labels = [], []
    for _ in range(n_graphs):
        a = rng.uniform(-0.3, 0.3)
        H = np.eye(3)
        H[:2, :2] = np.array([[np.cos(a), -np.sin(a)], [np.sin(a), np.cos(a)]]) @ np.array(
            [[1.0, rng.uniform(-0.05, 0.05)], [0.0, 1.0]])
        H[:2, 2] = rng.uniform(-1, 1, 2)
        k = int(rng.integers(keep[0], keep[1] + 1))
        kept = rng.permutation(n_points)[:k]
        graphs.append(Graph.from_points(_apply(H, base[kept]), edges="delaunay"))
        labels.append(kept)
    return graphs, MultiMatching(labels, n_points)


_AFFINITY = functools.partial(gaussian_edge_affinity, sigma2=0.01, attribute="length+angle")


@pytest.mark.filterwarnings("ignore::transync.exceptions.ConvergenceWarning")
@pytest.mark.parametrize("kwargs", [
    dict(solver="rrwm", sync="spectral", mode="offline"),
    dict(solver="rrwm"),                                   # S-RRWM, online
])
def test_match_collection_verified_recovers_planted_views(kwargs):
    """Mildly transformed views of one point set keeping 18-22 of 24 points, no noise:
    verified and synchronized, every correspondence is found and nothing else; the
    unverified pipeline does not get there on the same graphs (F1 0.85)."""
    graphs, truth = _landmark_collection(keep=(18, 22))
    res = match_collection(graphs, affinity=_AFFINITY, verify="affine", rng=0, progress=False,
                           **kwargs)
    pr = multimatching_precision_recall(res, truth)
    assert pr["precision"] == pr["recall"] == 1.0
    assert res.consistency == 1.0 and res.n_universe == 24
    info = res.info["verify"]
    assert info["model"] == "affine" and info["verified"].mean() > 0.8   # poor pairs fail
    assert info["n_inliers"].shape == (len(res.pairs),) and "verify" in res.timings
    plain = match_collection(graphs, affinity=_AFFINITY, verify=None, rng=0, progress=False,
                             **kwargs)
    assert multimatching_precision_recall(plain, truth)["f1"] < 0.9


@pytest.mark.filterwarnings("ignore::transync.exceptions.ConvergenceWarning")
def test_match_collection_verification_does_not_depend_on_the_executor():
    """Offline, the verification is spread over the executor like the pairwise stage; every
    pair draws its own seed first, so threads and processes give the serial result."""
    from concurrent.futures import ThreadPoolExecutor

    graphs, _ = _landmark_collection(n_graphs=7, keep=(16, 22), seed=4)
    kwargs = dict(affinity=_AFFINITY, solver="rrwm", sync="spectral", mode="offline",
                  verify="affine", rng=5, progress=False)
    serial = match_collection(graphs, **kwargs)
    with ThreadPoolExecutor(3) as pool:
        threads = match_collection(graphs, executor=pool, **kwargs)
    processes = match_collection(graphs, executor=2, **kwargs)
    for other in (threads, processes):
        np.testing.assert_array_equal(other.assignments, serial.assignments)
        for key in ("n_inliers", "verified"):
            np.testing.assert_array_equal(other.info["verify"][key], serial.info["verify"][key])


@pytest.mark.filterwarnings("ignore::transync.exceptions.ConvergenceWarning")
def test_match_collection_verified_pairwise_only():
    """sync=None: the verified pairwise maps themselves, far more precise than the matcher's
    (unshared nodes can still meet a free point inside the gate by chance)."""
    graphs, truth = _landmark_collection(keep=(18, 22))
    res = match_collection(graphs, affinity=_AFFINITY, sync=None, verify="affine", rng=0,
                           progress=False)
    plain = match_collection(graphs, affinity=_AFFINITY, sync=None, verify=None, rng=0,
                             progress=False)
    got = multimatching_precision_recall(res, truth)
    assert got["f1"] > multimatching_precision_recall(plain, truth)["f1"] + 0.15
    assert got["precision"] > 0.9 and res.matching is None


@pytest.mark.filterwarnings("ignore::transync.exceptions.ConvergenceWarning")
def test_match_collection_verified_equal_sizes():
    """Equal sizes (full permutations): verification then synchronization into n slots."""
    graphs, truth = _landmark_collection(n_graphs=5, keep=(24, 24), seed=3)
    res = match_collection(graphs, solver="rrwm", sync="spectral", mode="offline",
                           verify="similarity", verify_threshold=0.4, rng=0, progress=False)
    assert res.n_universe == 24 and res.accuracy(truth) == 1.0
    assert res.info["verify"]["threshold"] == 0.4


def test_match_collection_verify_refusals():
    graphs, _ = _landmark_collection(n_graphs=3)
    with pytest.raises(ValueError, match="`verify` must be one of .*'auto' or None, got 'rigid'"):
        match_collection(graphs, verify="rigid", progress=False)
    with pytest.raises(ValueError, match="verify_threshold"):
        match_collection(graphs, verify="affine", verify_threshold=-1.0, progress=False)
    with pytest.raises(ValueError, match="partial='dummies'"):
        match_collection(graphs, verify="affine", partial="dummies", progress=False)
    with pytest.raises(ValueError, match="`verify_threshold` sets the gate"):
        match_collection(graphs, verify=None, verify_threshold=0.5, progress=False)
    equal, _ = _landmark_collection(n_graphs=3, keep=(24, 24))
    with pytest.raises(ValueError, match=r"verify='auto' runs none of here \(the graphs are "
                                         r"not partial views"):
        match_collection(equal, verify_threshold=0.5, progress=False)
    with pytest.raises(ValueError, match="`verify` must be one of .*'auto' or None"):
        match_collection(graphs, verify="Auto", progress=False)
    for bad in ((), ("affine", "affine"), ("affine", "rigid"), ("affine", None), {"affine"},
                ("affine", ["homography"]), [["affine"]], ("affine", {"a": 1})):
        with pytest.raises((ValueError, TypeError),
                           match="`verify` (must be one of .* distinct ones|names a choice twice)"):
            match_collection(graphs, verify=bad, progress=False)
    no_points = [Graph(np.ones((4, 4)) - np.eye(4)) for _ in range(3)]
    with pytest.raises(ValueError, match="graph 0 has no points"):
        match_collection(no_points, verify="affine", progress=False)
    far = [Graph.from_points(np.random.default_rng(k).random((6, 2)) + 2e12, edges="full")
           for k in range(3)]
    weight = functools.partial(gaussian_edge_affinity, attribute="weight")
    with pytest.raises(ValueError, match=r"cannot check the matches of graphs\[0\] and "
                                         r"graphs\[1\] \(points1 = graphs\[0\]\.points"):
        match_collection(far, verify="affine", affinity=weight, progress=False)
    three_d = [Graph.from_points(np.random.default_rng(k).random((5, 3)), edges="full") for k in range(3)]
    with pytest.raises(ValueError, match="graph 0 has 3-d points"):
        match_collection(three_d, verify="homography", progress=False)


@pytest.mark.parametrize("kwargs", [dict(), dict(sync="orthogonal", mode="offline"),
                                    dict(solver="cao", sync="spectral")])
def test_match_collection_unverifiable_collection_matches_nothing(kwargs):
    """Three unrelated point sets of equal size: no pair verifies, so no node gets a partner
    (an evidence-free full permutation would be arbitrary), and the output stays consistent."""
    rng = np.random.default_rng(0)
    graphs = [Graph.from_points(rng.random((5, 2)), edges="full") for _ in range(3)]
    res = match_collection(graphs, verify="affine", rng=0, progress=False, **kwargs)
    assert not res.info["verify"]["verified"].any()
    assert np.all(res.assignments == -1) and res.consistency == 1.0
    assert all(np.all(lab == -1) for lab in res.matching.labels)


@pytest.mark.filterwarnings("ignore::transync.exceptions.ConvergenceWarning")
def test_match_collection_failed_pairs_do_not_inflate_the_universe():
    """Equal sizes, default gate: 6 of 10 pairs verify. The failed ones are unobserved, not
    evidence of disjoint graphs (as empty maps they doubled the estimate: 48 slots, F1 0.57)."""
    graphs, truth = _landmark_collection(n_graphs=5, keep=(24, 24), seed=3)
    for kwargs in (dict(), dict(sync="spectral", mode="offline"), dict(n_universe=24)):
        res = match_collection(graphs, affinity=_AFFINITY, verify="affine", rng=0,
                               progress=False, **kwargs)
        assert not res.info["verify"]["verified"].all()
        assert res.n_universe == 24 and res.accuracy(truth) == 1.0


def test_extreme_scales_and_a_far_point():
    """Coordinates near the float64 limits and one point 1e8 away from a unit cluster: the
    normalization keeps the geometry (no overflow warning, no underflowed gate)."""
    rng = np.random.default_rng(0)
    p = rng.random((20, 2))
    A = np.array([[0.9, -0.3], [0.4, 1.1]])
    for scale in (1e-300, 1e-170, 1e-155, 1e11):
        res = verify_assignment(p * scale, (p @ A.T) * scale, np.arange(20), rng=0)
        assert res.verified and res.n_inliers == 20 and 0 < res.threshold < np.inf
        np.testing.assert_allclose(res.transform[:2, :2], A, rtol=1e-6)
    far = np.vstack([p, [[1e8, 1e8]]])
    for model in ("affine", "similarity"):
        res = verify_assignment(far, far @ A.T + 2 if model == "affine" else 2 * far + 1,
                                np.arange(21), model=model, rng=0)
        assert res.verified and res.n_inliers == 21
    with pytest.raises(ValueError, match="`threshold` times the spacing"):
        verify_assignment(p * 1e11, p * 1e11, np.arange(20), threshold=1e300)


# ------------------------------------------------------------------ verify="auto" (the default)

@pytest.mark.filterwarnings("ignore::transync.exceptions.ConvergenceWarning")
@pytest.mark.parametrize("kwargs", [dict(), dict(sync="spectral", mode="offline"),
                                    dict(sync=None)])
def test_default_verifies_partial_views_with_points(kwargs):
    """Graphs of different sizes with 2-d points: the default is the affine-or-homography
    verification, exactly as if asked for (same seeds, same maps), and says so."""
    graphs, truth = _landmark_collection(keep=(18, 22))
    auto = match_collection(graphs, affinity=_AFFINITY, rng=0, progress=False, **kwargs)
    asked = match_collection(graphs, affinity=_AFFINITY, verify=["affine", "homography"],
                             rng=0, progress=False, **kwargs)
    np.testing.assert_array_equal(auto.assignments, asked.assignments)
    info = auto.info["verify"]
    assert info["model"] == ("affine", "homography") and info["auto"] and info["used"]
    assert set(info["pair_models"]) <= {"affine", "homography"}
    assert len(info["pair_models"]) == len(info["verified"]) == len(info["verified_first"])
    assert not asked.info["verify"]["auto"] and asked.info["verify"]["used"]
    assert multimatching_precision_recall(auto, truth)["f1"] > 0.9
    if kwargs.get("sync", "auto") is not None:
        assert auto.n_universe == 24 and auto.consistency == 1.0
        assert auto.info["n_universe_rule"].startswith("estimated from the verified maps")
    pickle.loads(pickle.dumps(auto))          # nothing unpicklable left in info


@pytest.mark.filterwarnings("ignore::transync.exceptions.ConvergenceWarning")
@pytest.mark.parametrize("case", ["equal sizes", "no points", "dummies"])
def test_default_verifies_nothing_outside_partial_views_with_points(case):
    """Equal sizes (where the quadratic model alone is exact on CMU House), graphs without
    points and the dummy-node baseline: the default runs no verification at all."""
    kwargs = {}
    if case == "equal sizes":
        graphs, _ = _landmark_collection(n_graphs=5, keep=(24, 24), seed=3)
    elif case == "no points":
        graphs = make_subgraph_collection(n_graphs=5, n_universe=10, p_keep=(0.6, 1.0),
                                          rng=0).graphs
    else:
        graphs, _ = _landmark_collection(n_graphs=5, keep=(18, 22))
        kwargs = dict(partial="dummies")
    auto = match_collection(graphs, rng=0, progress=False, **kwargs)
    off = match_collection(graphs, verify=None, rng=0, progress=False, **kwargs)
    assert "verify" not in auto.info and "verify" not in auto.timings
    np.testing.assert_array_equal(auto.assignments, off.assignments)


@pytest.mark.filterwarnings("ignore::transync.exceptions.ConvergenceWarning")
@pytest.mark.parametrize("kwargs", [dict(), dict(sync="spectral", mode="offline"),
                                    dict(sync=None)])
def test_default_drops_a_verification_the_geometry_does_not_support(kwargs):
    """Partial graphs whose points are unrelated between graphs (not one rigid or planar
    scene): no pair verifies, so the default keeps the unverified pipeline's output, exactly
    (the random stream is rewound), instead of leaving every node unplaced."""
    c = make_subgraph_collection(n_graphs=6, n_universe=12, p_keep=(0.6, 1.0),
                                 deformation=0.02, rng=1)
    rng = np.random.default_rng(0)
    graphs = [Graph(g.adjacency, edge_features=g.edge_features,
                    points=rng.random((g.n_nodes, 2))) for g in c.graphs]
    auto = match_collection(graphs, rng=3, progress=False, **kwargs)
    off = match_collection(graphs, verify=None, rng=3, progress=False, **kwargs)
    info = auto.info["verify"]
    assert info["auto"] and not info["used"] and info["verified"].mean() < 0.5
    np.testing.assert_array_equal(auto.assignments, off.assignments)
    assert np.mean(auto.assignments >= 0) > 0.5               # not every node unplaced
    if auto.matching is not None:
        assert auto.n_universe == off.n_universe
        assert auto.info["n_universe_rule"] == off.info["n_universe_rule"]
        assert auto.accuracy(c.ground_truth) == off.accuracy(c.ground_truth) > 0.8
    pickle.loads(pickle.dumps(auto))


@pytest.mark.filterwarnings("ignore::transync.exceptions.ConvergenceWarning")
@pytest.mark.parametrize("n_graphs, used", [(6, False), (8, True)])
def test_default_keeps_the_verification_from_70_percent_of_pairs(n_graphs, used):
    """One graph of unrelated points among mild views of one point set: its pairs fail (but
    for one chance fit with 8 graphs). With 6 graphs 10 of 15 pairs verify affinely (0.67:
    below the 70 % the default asks for, its output is verify=None's); with 8 graphs 22 of 28
    (0.79: the verified maps are used). The share of the first model decides: the homography
    alternative verifies a pair more with 8 graphs, and counts for the maps only."""
    graphs, _ = _landmark_collection(n_graphs=n_graphs, keep=(18, 22), seed=1)
    graphs[-1] = Graph.from_points(np.random.default_rng(9).random((20, 2)), edges="delaunay")
    res = match_collection(graphs, affinity=_AFFINITY, mode="offline", sync="spectral", rng=0,
                           progress=False)
    info = res.info["verify"]
    assert info["verified_first"].sum() == {6: 10, 8: 22}[n_graphs] and info["used"] is used
    assert np.all(info["verified"] >= info["verified_first"])
    off = match_collection(graphs, affinity=_AFFINITY, mode="offline", sync="spectral",
                           verify=None, rng=0, progress=False)
    assert np.array_equal(res.assignments, off.assignments) is not used


def _perspective_collection(seed, n_views=6, n=24, strength=0.6):
    """Partial views of one plane in strong perspective: a homography explains every pair,
    an affine map only the milder ones."""
    rng = np.random.default_rng(seed)
    base = rng.random((n, 2))
    graphs = []
    for _ in range(n_views):
        H = np.eye(3)
        H[:2, :2] += 0.1 * rng.standard_normal((2, 2))
        H[:2, 2] = rng.uniform(-1, 1, 2)
        H[2, :2] = strength * rng.uniform(-1, 1, 2)
        kept = rng.permutation(np.flatnonzero(rng.random(n) < 0.85))
        graphs.append(Graph.from_points(_apply(H, base[kept]), edges="delaunay"))
    return graphs


@pytest.mark.filterwarnings("ignore::transync.exceptions.ConvergenceWarning")
def test_default_decides_on_the_first_model_and_keeps_the_better_per_pair():
    """Views in perspective: the affine map verifies 6 of 15 pairs, either model 11 (0.73).
    The 70 % rule counts the affine ones, exactly those verify='affine' verifies (the first
    candidate runs as the model alone), so the default falls back to verify=None's output;
    each pair kept the model with more matches (the homography only when it had more)."""
    from transync.datasets import LANDMARK_AFFINITY

    graphs = _perspective_collection(7)
    kw = dict(affinity=functools.partial(gaussian_edge_affinity, **LANDMARK_AFFINITY), rng=0,
              progress=False, mode="offline", sync="spectral")
    auto = match_collection(graphs, **kw)
    both = match_collection(graphs, verify=("affine", "homography"), **kw)
    affine = match_collection(graphs, verify="affine", **kw)
    off = match_collection(graphs, verify=None, **kw)
    info, alone = auto.info["verify"], affine.info["verify"]
    np.testing.assert_array_equal(info["verified_first"], alone["verified"])
    assert info["verified_first"].sum() == 6 and info["verified"].sum() == 11
    assert info["auto"] and not info["used"]
    np.testing.assert_array_equal(auto.assignments, off.assignments)
    # forced, the A/H maps are used, and differ from the affine ones where a homography won
    assert both.info["verify"]["used"] and not np.array_equal(both.assignments,
                                                              affine.assignments)
    homog = info["pair_models"] == "homography"
    assert homog.sum() == 11 - 6 + np.sum(homog & alone["verified"])
    assert np.all(info["n_inliers"][homog] > alone["n_inliers"][homog])
    np.testing.assert_array_equal(info["n_inliers"][~homog], alone["n_inliers"][~homog])


@pytest.mark.filterwarnings("ignore::transync.exceptions.ConvergenceWarning")
def test_default_fallback_reports_the_input_as_verify_none_does():
    """108 graphs and more: the input-consistency report samples triangles from the random
    stream that the online output's builder also draws from; when the default drops its
    verification, both run in verify=None's order (the report was 0.578 against 0.574)."""
    N = 110
    c = make_subgraph_collection(n_graphs=N, n_universe=6, p_keep=(0.6, 1.0),
                                 deformation=0.02, rng=1)
    rng = np.random.default_rng(0)
    graphs = [Graph(g.adjacency, edge_features=g.edge_features,
                    points=rng.random((g.n_nodes, 2))) for g in c.graphs]
    pairs = np.sort(np.array([(i, (i + k) % N) for k in (1, 2) for i in range(N)]), axis=1)
    auto = match_collection(graphs, pairs=pairs, rng=3, progress=False)
    off = match_collection(graphs, pairs=pairs, rng=3, progress=False, verify=None)
    assert not auto.info["verify"]["used"]
    assert auto.input_consistency == off.input_consistency
    np.testing.assert_array_equal(auto.assignments, off.assignments)


def test_default_falls_back_when_the_points_are_refused():
    """Coordinates beyond verify_assignment's range: asked for by name, an error naming the
    graphs; by default, no verification (the reason kept) and verify=None's output."""
    base = np.random.default_rng(0).random((8, 2))
    graphs = [Graph.from_points(base[:k] + 2e12, edges="full") for k in (5, 6, 7)]
    res = match_collection(graphs, rng=0, progress=False)
    off = match_collection(graphs, verify=None, rng=0, progress=False)
    info = res.info["verify"]
    assert info["auto"] and not info["used"] and "at most 1e+12" in info["refused"]
    np.testing.assert_array_equal(res.assignments, off.assignments)
    assert res.n_universe == off.n_universe
    with pytest.raises(ValueError, match=r"`verify='affine'` cannot check the matches"):
        match_collection(graphs, verify="affine", rng=0, progress=False)


@pytest.mark.parametrize("model", ["affine", "homography", ("affine", "homography")])
def test_a_mirroring_transform_does_not_verify_unless_asked(model):
    # two views are not mirror images: a matcher's mirrored answer (lengths are the same in a
    # mirror) was fitted by a mirroring affine map and "verified" with no right match
    rng = np.random.default_rng(3)
    p1 = rng.random((14, 2))
    mirror = np.array([[-1.0, 0.0], [0.0, 1.0]])
    p2 = p1 @ mirror.T + [3.0, 1.0]
    ident = np.arange(14)
    res = verify_assignment(p1, p2, ident, model=model, rng=0)
    assert not res.verified and np.all(res.assignment == -1)
    ok = verify_assignment(p1, p2, ident, model=model, reflections=True, rng=0)
    assert ok.verified and ok.assignment.tolist() == ident.tolist()
    assert np.linalg.det(ok.transform) < 0
    # the same points turned instead of mirrored verify either way
    c, s = np.cos(0.7), np.sin(0.7)
    turned = p1 @ np.array([[c, -s], [s, c]]).T + [3.0, 1.0]
    for refl in (False, True):
        r = verify_assignment(p1, turned, ident, model=model, reflections=refl, rng=0)
        assert r.verified and r.assignment.tolist() == ident.tolist()
    with pytest.raises(TypeError, match="reflections"):
        verify_assignment(p1, p2, ident, reflections="no")
