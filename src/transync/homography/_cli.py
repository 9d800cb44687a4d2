"""``transync homography IMAGE... --reference 0 --out DIR``: plane homographies, masks, report."""

from __future__ import annotations

import json
import time
from pathlib import Path

__all__ = ["add_homography_parser"]


def _cmd_homography(args) -> int:
    import cv2
    import numpy as np

    from ._pipeline import estimate_plane_homographies

    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    res = estimate_plane_homographies(args.images, reference=args.reference,
                                      dense=not args.no_dense, segment=not args.no_segment,
                                      method=args.method, threshold=args.threshold,
                                      n_features=args.features, max_iter=args.max_iter,
                                      dense_target=args.dense_target,
                                      verbose=args.verbose)
    seconds = time.perf_counter() - t0
    names = [str(p) for p in args.images]
    payload = {
        "reference": res.reference,
        "convention": "homographies[i] maps pixel (x, y, 1) of image i into the reference image",
        "images": names,
        "homographies": [None if not np.all(np.isfinite(H)) else H.tolist()
                         for H in res.homographies],
        "sparse_homographies": [None if not np.all(np.isfinite(H)) else H.tolist()
                                for H in res.sparse_homographies],
        "failed_pairs": [[int(i), int(j), str(why)] for i, j, why in res.pairwise.failed],
        "converged": bool(res.converged),
        "n_iter": int(res.n_iter),
        "seconds": seconds,
        "history": res.info["history"],
    }
    (out / "homographies.json").write_text(json.dumps(payload, indent=2, default=float))
    (out / "masks").mkdir(exist_ok=True)
    for k, m in enumerate(res.masks):
        cv2.imwrite(str(out / "masks" / f"mask_{k:03d}.png"), m.astype(np.uint8) * 255)
    mean = np.nan_to_num(res.mean_image)
    cv2.imwrite(str(out / "mean_warped.png"), np.clip(np.round(mean), 0, 255).astype(np.uint8))
    sync = res.info["sync"]
    lines = [
        "# transync homography", "",
        f"- images: {len(names)}, reference: {res.reference} ({names[res.reference]})",
        f"- pairs estimated: {int(res.pairwise.mask.sum() // 2)}, failed: "
        f"{len(res.pairwise.failed)}, rejected by robust synchronization: "
        f"{int((sync.mask & ~sync.inliers).sum() // 2)}",
        f"- dense refinement: {'off' if args.no_dense else 'on'}, segmentation: "
        f"{'off' if args.no_segment else 'on'}, rounds: {res.n_iter}, converged: "
        f"{res.converged}",
        f"- plane fraction per view: "
        f"{', '.join(f'{m.mean():.2f}' for m in res.masks)}",
        f"- time: {seconds:.1f} s "
        f"({', '.join(f'{k} {v:.1f}' for k, v in res.info['seconds'].items())})",
        "", "| round | max corner change (px) | plane fraction |", "|---|---|---|",
    ]
    for h in res.info["history"]:
        lines.append(f"| {h['iteration']} | {h['max_corner_change']:.4f} | "
                     f"{h['plane_fraction']:.3f} |")
    lines += ["", "Files: `homographies.json`, `masks/mask_NNN.png` (255 = plane), "
              "`mean_warped.png`."]
    (out / "report.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines[:7]))
    print(f"written to {out}")
    return 0


def add_homography_parser(subparsers) -> None:
    """Register the ``homography`` subcommand on an ``argparse`` subparsers object."""
    p = subparsers.add_parser(
        "homography", help="homographies of the dominant plane across images, with plane masks")
    p.add_argument("images", nargs="+", metavar="IMAGE", help="image files (2 or more)")
    p.add_argument("--reference", type=int, default=0, help="reference image index (default 0)")
    p.add_argument("--out", default="transync-homography", help="output folder")
    p.add_argument("--no-dense", action="store_true", help="skip the dense photometric step")
    p.add_argument("--no-segment", action="store_true", help="skip the plane segmentation")
    p.add_argument("--method", default="ransac",
                   choices=["ransac", "lmeds", "rho", "usac_default", "usac_magsac",
                            "usac_accurate", "usac_prosac", "usac_fast"])
    p.add_argument("--threshold", type=float, default=3.0, help="RANSAC threshold (pixels)")
    p.add_argument("--features", type=int, default=2000, help="SIFT features per image")
    p.add_argument("--max-iter", type=int, default=3, help="segmentation + dense rounds")
    p.add_argument("--dense-target", default="auto", choices=["auto", "mean", "reference"])
    p.add_argument("--verbose", action="store_true")
    p.set_defaults(func=_cmd_homography)
