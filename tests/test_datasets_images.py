"""Tests for the data home and the real-data loaders (Oxford, HPatches, graf, AdelaideRMF)."""

import numpy as np
import pytest

import cv2
from transync.datasets._home import data_home
from transync.datasets._image_loaders import (
    list_adelaidermf,
    load_adelaidermf,
    load_graf,
    load_hpatches_sequence,
    load_oxford_sequence,
)

HOME = data_home(required=False)


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


def test_data_home_env(monkeypatch, tmp_path):
    monkeypatch.setenv("TRANSYNC_DATA", str(tmp_path))
    assert data_home() == tmp_path
    (tmp_path / "sub").mkdir()
    assert data_home(subfolder="sub") == tmp_path / "sub"
    assert data_home(required=False, subfolder="nope") is None


def test_data_home_missing_names_both(monkeypatch, tmp_path):
    import transync.datasets._home as home

    monkeypatch.setenv("TRANSYNC_DATA", str(tmp_path / "missing"))
    monkeypatch.setattr(home, "_default_home", lambda: tmp_path / "also-missing")
    assert data_home(required=False) is None
    with pytest.raises(FileNotFoundError, match="TRANSYNC_DATA") as exc:
        data_home()
    assert "also-missing" in str(exc.value)


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


def test_loader_errors(tmp_path):
    with pytest.raises(FileNotFoundError, match="Oxford"):
        load_oxford_sequence(tmp_path)
    (tmp_path / "img1.png").write_bytes(b"")
    cv2.imwrite(str(tmp_path / "img1.png"), np.zeros((4, 4), np.uint8))
    cv2.imwrite(str(tmp_path / "img2.png"), np.zeros((4, 4), np.uint8))
    (tmp_path / "H1to2p").write_text("1 0 0 0 1 0")
    with pytest.raises(ValueError, match="9 numbers"):
        load_oxford_sequence(tmp_path)


needs_data = pytest.mark.skipif(HOME is None, reason="real data folder not found "
                                                     "(TRANSYNC_DATA or ../shared/data)")


@needs_data
def test_graf_1_to_3():
    from transync.homography import estimate_plane_homographies

    g = load_graf()
    assert g.n_views == 2 and g.images[0].shape == (640, 800, 3)
    res = estimate_plane_homographies(g.images, max_iter=3, dense_target="reference",
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


@needs_data
def test_adelaidermf_sequential_planes():
    from transync.homography._multiplane import extract_planes, misclassification_error

    names = list_adelaidermf()
    assert len(names) >= 10
    errs = []
    for name in ("elderhalla", "ladysymon", "napiera"):
        d = load_adelaidermf(name)
        assert d.x1.shape == d.x2.shape and d.x1.shape[0] == d.labels.size
        res = extract_planes(d.x1, d.x2, threshold=5.0)
        errs.append(misclassification_error(res.labels, d.labels))
    assert np.mean(errs) < 0.15
