"""Tests for the real-data loaders (Oxford, HPatches, graf, AdelaideRMF) on fixtures and real data.

Error paths on malformed files: tests/datasets/test_loaders.py.
"""

import numpy as np
import pytest

import cv2
from transync.datasets import (
    list_adelaidermf,
    load_adelaidermf,
    load_graf,
    load_hpatches_sequence,
    load_oxford_sequence,
)



def _planted(tmp_path, names, hnames, fmt):
    rng = np.random.default_rng(0)
    base = cv2.GaussianBlur((rng.random((60, 80, 3)) * 255).astype(np.uint8), (0, 0), 1.0)
    Hs = [np.eye(3)]
    cv2.imwrite(str(tmp_path / names[0]), base)
    for k, (name, hname) in enumerate(zip(names[1:], hnames), start=2):
        H1k = np.array([[1.0, 0.02 * k, 3.0 * k], [-0.01 * k, 1.0, -2.0], [1e-4 * k, 0, 1.0]])
        cv2.imwrite(str(tmp_path / name), cv2.warpPerspective(base, H1k, (80, 60)))
        (tmp_path / hname).write_text(fmt(H1k))
        Hs.append(np.linalg.inv(H1k))
    return Hs


@pytest.mark.parametrize("kind", ["oxford", "hpatches"])
def test_sequence_loaders_on_fixtures(tmp_path, kind):
    if kind == "oxford":
        names = [f"img{k}.ppm" for k in range(1, 4)]
        hnames = [f"H1to{k}p" for k in range(2, 4)]
        fmt = lambda H: "\n".join(" ".join(f"{v:.10e}" for v in row) for row in H) + "\n"  # noqa: E731
        loader = load_oxford_sequence
    else:
        names = [f"{k}.ppm" for k in range(1, 4)]
        hnames = [f"H_1_{k}" for k in range(2, 4)]
        fmt = lambda H: "\n".join("  ".join(f"{v:.12g}" for v in row) for row in H)  # noqa: E731
        loader = load_hpatches_sequence
    Hs = _planted(tmp_path, names, hnames, fmt)
    seq = loader(tmp_path)
    assert seq.n_views == 3 and seq.images[0].shape == (60, 80, 3)
    for k in range(3):
        expected = Hs[k] / np.cbrt(np.linalg.det(Hs[k]))
        np.testing.assert_allclose(seq.homographies[k], expected, rtol=1e-8, atol=1e-10)
    # the loaded homography maps image k into image 0: warping k back reproduces image 0
    back = cv2.warpPerspective(seq.images[2], seq.homographies[2], (80, 60))
    inner = np.s_[15:45, 20:60]
    assert np.median(np.abs(back[inner].astype(float) - seq.images[0][inner])) < 20
    # an image numbered 0 is not silently taken as the reference (before: "H1to1p not found")
    stray = tmp_path / ("img0.png" if kind == "oxford" else "0.png")
    cv2.imwrite(str(stray), np.zeros((8, 8), np.uint8))
    with pytest.raises(ValueError, match=f"{stray.name}: image index 0, but the format numbers "
                                         "images from 1"):
        loader(tmp_path)




@pytest.mark.dataset("oxford-graf")
def test_graf_1_to_3():
    from transync.homography import estimate_plane_homographies

    g = load_graf()
    assert g.n_views == 2 and g.images[0].shape == (640, 800, 3)
    res = estimate_plane_homographies(g.images, max_iter=3, dense_target="reference", rng=0,
                                      n_features=2000)
    # transfer error over a grid of graf3 pixels that land inside graf1
    ys, xs = np.mgrid[20:620:20, 20:780:20]
    p = np.stack([xs.ravel(), ys.ravel(), np.ones(xs.size)]).astype(float)
    qt = g.homographies[1] @ p
    qe = res.homographies[1] @ p
    qt, qe = qt[:2] / qt[2], qe[:2] / qe[2]
    inside = (qt[0] > 0) & (qt[0] < 799) & (qt[1] > 0) & (qt[1] < 639)
    err = np.linalg.norm(qt - qe, axis=0)[inside]
    assert inside.sum() > 300
    assert np.median(err) < 1.5 and err.mean() < 2.0


@pytest.mark.dataset("adelaidermf")
def test_adelaidermf_sequential_planes():
    from transync.homography import extract_planes, misclassification_error

    names = list_adelaidermf()
    assert len(names) >= 10
    errs = []
    for name in ("elderhalla", "ladysymon", "napiera"):
        d = load_adelaidermf(name)
        assert d.x1.shape == d.x2.shape and d.x1.shape[0] == d.labels.size
        res = extract_planes(d.x1, d.x2, threshold=5.0, rng=0)
        errs.append(misclassification_error(res.labels, d.labels))
    assert np.mean(errs) < 0.15


@pytest.mark.dataset("adelaidermf")
def test_all_adelaidermf_files_pass_validation():
    """Every real .mat file satisfies the checks the loader applies to the format."""
    names = list_adelaidermf()
    for name in names:
        d = load_adelaidermf(name)
        n = d.labels.size
        assert d.x1.shape == d.x2.shape == (n, 2) and np.all(np.isfinite(d.x1))
        assert d.labels.min() >= 0 and d.n_planes >= 1
        assert d.img1.ndim == 3 and d.img1.dtype == np.uint8


@pytest.mark.dataset("oxford-graf")
def test_graf_ground_truth_from_xml():
    g = load_graf()
    H = np.linalg.inv(g.homographies[1])          # graf1 -> graf3, up to scale
    H = H / H[2, 2]
    np.testing.assert_allclose(H[0], [7.6285898e-01, -2.9922929e-01, 2.2567123e+02], rtol=1e-6)
    np.testing.assert_allclose(np.linalg.det(g.homographies), 1.0, rtol=1e-9)
