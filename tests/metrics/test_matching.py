import numpy as np
import pytest

from transync.metrics import affinity_score, matching_accuracy, matching_precision_recall


def test_accuracy_ignores_outlier_rows():
    truth = np.array([1, 0, -1, -1])
    assert matching_accuracy(np.array([1, 0, 2, 3]), truth) == 1.0
    assert matching_accuracy(np.array([0, 1, 2, 3]), truth) == 0.0
    assert matching_accuracy(np.array([1, -1, 2, 3]), truth) == 0.5


def test_precision_recall_counts_spurious_matches():
    truth = np.array([0, 1, -1])
    pr = matching_precision_recall(np.array([0, -1, 1]), truth)
    assert pr["precision"] == 0.5 and pr["recall"] == 0.5 and pr["f1"] == 0.5
    assert matching_precision_recall(truth, truth)["f1"] == 1.0


def test_affinity_score_dense_matches_formula(rng):
    n1, n2 = 3, 4
    K = rng.random((n1 * n2, n1 * n2))
    a = np.array([2, 0, 3])
    x = np.zeros(n1 * n2)
    x[a * n1 + np.arange(n1)] = 1          # column-major vec: index a * n1 + i
    assert affinity_score(K, a, n2=n2) == pytest.approx(x @ K @ x)
    assert affinity_score(K, a, n2=n2, normalize_by=a) == pytest.approx(1.0)


def test_metric_errors():
    with pytest.raises(ValueError, match="same length"):
        matching_accuracy([0, 1], [0, 1, 2])
    with pytest.raises(TypeError, match="n2"):
        affinity_score(np.eye(4), [0, 1])
    with pytest.raises(ValueError, match="shape"):
        affinity_score(np.eye(5), [0, 1], n2=2)
    K = np.zeros((2, 2))
    K[0, 0] = np.inf                             # inf * 0 would be a silent NaN score
    with pytest.raises(ValueError, match="`affinity`"):
        affinity_score(K, [1], n2=2)
    with pytest.raises(ValueError, match="`affinity`"):
        affinity_score(np.full((1, 1), np.nan), [0], n2=1)


def test_affinity_score_input_contract():
    """``n2`` and ``normalize_by`` checked by name; entries whose products overflow refused
    (before: NaN from 0 * inf, a string ``n2`` repeated into the shape message)."""
    K = np.ones((4, 4))
    with pytest.raises(TypeError, match="`n2` must be an int, got str"):
        affinity_score(K, [0, 1], n2="2")
    with pytest.raises(TypeError, match="`n2` must be an int, got bool"):
        affinity_score(K, [0, 1], n2=True)
    with pytest.raises(ValueError, match="`n2` must be >= 1, got 0"):
        affinity_score(K, [0, 1], n2=0)
    with pytest.raises(ValueError, match="`normalize_by` must be an assignment of the same 2"):
        affinity_score(K, [0, 1], n2=2, normalize_by=[0])
    with pytest.raises(ValueError, match="`affinity` is too large"):
        affinity_score(np.full((4, 4), 1e308), [0, 1], n2=2)
    assert affinity_score(K, [0, 1], n2=2, normalize_by=[1, 0]) == 1.0


def test_affinity_score_names_what_is_wrong():
    """normalize_by out of range was reported as `assignment`; an object with score() but no
    n2 raised AttributeError."""
    with pytest.raises(ValueError, match=r"`normalize_by` entries must be < n2=2, got 5"):
        affinity_score(np.ones((4, 4)), [0, 1], n2=2, normalize_by=[5, 0])

    class NoN2:
        def score(self, X):
            return 1.0

    with pytest.raises(TypeError, match=r"`affinity` must be an Affinity .* without .n2"):
        affinity_score(NoN2(), [0, 1])
    with pytest.raises(ValueError, match=r"`affinity` must fit in float64"):
        affinity_score([[2**1100] * 4] * 4, [0, 1], n2=2)


def test_ragged_assignments_are_named():
    with pytest.raises(TypeError, match=r"`assignment` must be a 1-d integer index array, got a "
                                        r"ragged sequence"):
        matching_accuracy([[0], [1, 2]], [0, 1])


def test_homography_metric_inputs_are_checked():
    from transync.metrics import brenner_focus, segmentation_scores

    img = np.zeros((8, 8))
    img[:, 4:] = 1e154                      # each square finite, their mean not
    with pytest.raises(ValueError, match=r"`image` values are too large for the focus measure"):
        brenner_focus(img)
    with pytest.raises(TypeError, match=r"`image` must be an array, got a ragged"):
        brenner_focus([[0.0, 1.0], [1.0]])
    with pytest.raises(ValueError, match=r"`valid` must have the shape of `pred` \(1, 3\)"):
        segmentation_scores([[1, 1, 0]], [[1, 0, 0]], valid=np.ones((2, 2), bool))
    with pytest.raises(TypeError, match=r"`pred` must be a boolean \(or numeric\) mask"):
        segmentation_scores(["False", "False"], [False, False])      # "False" read as True
    with pytest.raises(ValueError, match=r"`truth` must be finite"):
        segmentation_scores([0.0, 1.0], [np.nan, 1.0])
    assert segmentation_scores([1, 0], [1.0, 0.0])["f1"] == 1.0


def test_corner_error_of_identical_maps_is_zero_or_refused():
    """image_size = 1e308 gave inf for two identical homographies (corners overflow)."""
    from transync.metrics import corner_error

    H = 2 * np.eye(3)
    with pytest.raises(ValueError, match=r"`image_size` .* entries in \[1, 1e\+12\]"):
        corner_error(H, H, image_size=(1e308, 1e308))
    assert corner_error(H, H, image_size=(1e12, 1e12)) == 0.0
    # a homography's scale does not matter, up to 1e308 (was inf: its products overflowed)
    for big in (1e308 * np.eye(3), 1e297 * H):
        assert corner_error(big, H, image_size=(640, 480)) < 1e-9
        assert corner_error(H, big, image_size=(1e12, 1e12)) < 1e-3


@pytest.mark.parametrize("size", [(640, 480), (10, 10), (11, 11)])
def test_pairwise_corner_error_counts_identical_views_as_full_overlap(size):
    # the overlap was divided by (w, h) for a polygon spanning (w - 1, h - 1): identical views
    # overlapped by (w - 1)(h - 1) / (w h) < 1 and were dropped at min_overlap=1
    from transync.metrics import pairwise_corner_error

    S = np.stack([np.eye(3)] * 2)
    np.testing.assert_array_equal(
        pairwise_corner_error(S, S, image_size=size, min_overlap=1.0), [0.0, 0.0])


def test_pairwise_corner_error_overlap_is_the_shared_fraction_of_the_view():
    from transync.metrics import pairwise_corner_error

    # view 1 shifted by 5 of the 10 pixels between the corners of an 11 x 11 view: half shared
    shift = np.array([[1.0, 0, 5], [0, 1, 0], [0, 0, 1]])
    H = np.stack([np.eye(3), shift])
    assert pairwise_corner_error(H, H, image_size=(11, 11), min_overlap=0.5).size == 2
    assert pairwise_corner_error(H, H, image_size=(11, 11), min_overlap=0.51).size == 0


def test_brenner_focus_is_the_same_at_any_bit_depth():
    # only uint8 was scaled to [0, 1]: the 16-bit read of one picture scored 4e9 times higher
    from transync.metrics import brenner_focus

    img = (np.arange(36).reshape(6, 6) * 7).astype(np.uint8)
    ref = brenner_focus(img)
    assert ref > 0
    for same in (img.astype(np.uint16) * 257, img / 255.0, np.dstack([img] * 3),
                 np.dstack([img.astype(np.uint16) * 257] * 4)):
        assert brenner_focus(same) == pytest.approx(ref, rel=1e-12)


def test_affinity_score_names_a_short_assignment():
    # an Affinity object's own shape check named its internal `X`
    from transync.graphs import Graph
    from transync.matching import gaussian_edge_affinity
    from transync.metrics import affinity_score

    g = Graph.from_points(np.random.default_rng(0).random((4, 2)), edges="full")
    aff = gaussian_edge_affinity(g, g, sigma2=0.15)
    with pytest.raises(ValueError, match=r"`assignment` must have one entry per node of the "
                                         r"affinity's first graph \(4\), got 3"):
        affinity_score(aff, [0, 1, 2])
    assert affinity_score(aff, [0, 1, 2, 3]) > affinity_score(aff, [1, 0, 2, 3])
