"""``transync homography IMAGE... --reference 0 --out DIR``: plane homographies, masks, report."""

from __future__ import annotations

import argparse
import contextlib
import json
import re
import time
from pathlib import Path

from ._common import (CLIError, check_output_folder, input_file, int_at_least,
                      new_output_folder, positive_float, positive_int, seed_int)

__all__ = ["add_parser"]

RANSAC = ["ransac", "lmeds", "rho", "usac_default", "usac_magsac", "usac_accurate",
          "usac_prosac", "usac_fast"]


def _check_images(paths) -> None:
    import cv2

    # the CLI owns its process: OpenCV's own warnings on damaged files would break the one-line
    # error contract (the failure itself is reported below, naming the file)
    cv2.utils.logging.setLogLevel(cv2.utils.logging.LOG_LEVEL_SILENT)
    if len(paths) < 2:
        raise CLIError(f"need at least 2 images, got {len(paths)}")
    for path in paths:
        if Path(path).is_dir():
            raise CLIError(f"{path}: a folder, not an image file (list the images, e.g. "
                           f"{path}/*.png)")
        p = input_file(path, "an image file")
        if not cv2.haveImageReader(str(p)):
            raise CLIError(f"{path}: not an image format OpenCV can read")


@contextlib.contextmanager
def _stage_log(enabled: bool):
    """Progress on stderr while the pipeline runs: one line per stage (sparse pairs, each
    dense round); the pipeline adds a bar over the rounds."""
    if not enabled:
        yield
        return
    import logging
    import sys

    from tqdm.auto import tqdm

    class _AboveTheBar(logging.Handler):    # a line of its own, not glued to the round bar
        def emit(self, record):
            tqdm.write(self.format(record), file=sys.stderr)

    handler = _AboveTheBar()
    handler.setFormatter(logging.Formatter("transync homography: %(message)s"))
    log = logging.getLogger("transync.homography")
    level = log.level
    log.addHandler(handler)
    log.setLevel(logging.INFO)
    try:
        yield
    finally:
        log.removeHandler(handler)
        log.setLevel(level)


def _estimate(args):
    from ..exceptions import DegenerateInputError
    from ..homography import estimate_plane_homographies

    options = dict(reference=args.reference, dense=not args.no_dense,
                   segment=not args.no_segment, method=args.method, threshold=args.threshold,
                   n_features=args.features, max_iter=args.max_iter,
                   dense_target=args.dense_target, rng=args.seed)
    try:
        with _stage_log(enabled=not args.no_progress):
            return estimate_plane_homographies(list(args.images), verbose=not args.no_progress,
                                               **options)
    except DegenerateInputError as exc:
        raise CLIError(f"the {len(args.images)} images could not be related: {exc}") from exc
    except (ValueError, TypeError) as exc:
        msg = str(exc)
        for k, name in enumerate(args.images):   # name the files the user gave, not indices
            msg = msg.replace(f"`images[{k}]`: `{name}`:", f"{name}:")  # named twice otherwise
            msg = msg.replace(f"`images[{k}]`", str(name))
        raise CLIError(msg) from exc


def _cmd_homography(args) -> int:
    import numpy as np

    check_output_folder(args.out)             # before the estimate, not after
    _check_images(args.images)
    if not 0 <= args.reference < len(args.images):
        raise CLIError(f"--reference must be an image index in [0, {len(args.images) - 1}], got "
                       f"{args.reference}")
    t0 = time.perf_counter()
    res = _estimate(args)
    seconds = time.perf_counter() - t0
    names = [str(p) for p in args.images]
    finite = [bool(np.all(np.isfinite(H))) for H in res.homographies]
    if not any(f for k, f in enumerate(finite) if k != res.reference):
        raise CLIError("no image could be linked to the reference: no homography was estimated")
    payload = {
        "reference": res.reference,
        "convention": "homographies[i] maps pixel (x, y, 1) of image i into the reference image",
        "images": names,
        "homographies": [H.tolist() if ok else None for H, ok in zip(res.homographies, finite)],
        "sparse_homographies": [None if not np.all(np.isfinite(H)) else H.tolist()
                                for H in res.sparse_homographies],
        "failed_pairs": [[int(i), int(j), str(why)] for i, j, why in res.pairwise.failed],
        "converged": bool(res.converged),
        "n_iter": int(res.n_iter),
        "seconds": seconds,
        "history": res.info["history"],
    }
    # an earlier run's masks of images this run lacks: removed once this run's files are in
    stale = _stale_masks(Path(args.out) / "masks", len(res.masks))
    with new_output_folder(args.out) as stage:
        lines = _write_outputs(stage, res, payload, args, names, seconds, stale)
    out = Path(args.out)
    for path in stale:
        path.unlink(missing_ok=True)
    print("\n".join(lines[:7] + [line for line in lines if line.startswith("- removed")]))
    print(f"written to {out}")
    return 0


def _write_outputs(out: Path, res, payload: dict, args, names, seconds,
                   stale: list[Path]) -> list[str]:
    import numpy as np

    (out / "homographies.json").write_text(json.dumps(payload, indent=2, default=float))
    (out / "masks").mkdir(exist_ok=True)
    for k, m in enumerate(res.masks):
        _imwrite(out / "masks" / f"mask_{k:03d}.png", m.astype(np.uint8) * 255)
    mean = np.nan_to_num(res.mean_image)
    _imwrite(out / "mean_warped.png", np.clip(np.round(mean), 0, 255).astype(np.uint8))
    sync = res.info["sync"]
    lines = [
        "# transync homography", "",
        f"- images: {len(names)}, reference: {res.reference} ({names[res.reference]})",
        f"- pairs estimated: {int(res.pairwise.mask.sum() // 2)}, failed: "
        f"{len(res.pairwise.failed)}, rejected by robust synchronization: "
        f"{int((sync.mask & ~sync.inliers).sum() // 2)}",
        _dense_line(res, args),
        f"- segmentation: {'off' if args.no_segment else 'on'}, rounds: {res.n_iter}, "
        f"converged: {res.converged}{_unconverged_note(res)}",
        _views_line(res, names),
        f"- plane fraction per view: "
        f"{', '.join(f'{m.mean():.2f}' for m in res.masks)}",
        f"- time: {seconds:.1f} s with reading the images (pipeline stages: "
        f"{', '.join(f'{k} {v:.1f}' for k, v in res.info['seconds'].items())})",
        "", "| round | max corner change (px) | plane fraction |", "|---|---|---|",
    ]
    for h in res.info["history"]:
        lines.append(f"| {h['iteration']} | {h['max_corner_change']:.4f} | "
                     f"{h['plane_fraction']:.3f} |")
    lines += ["", "Files:", "",
              "- `homographies.json`: `homographies[i]` maps pixel (x, y, 1) of image i into the "
              "reference image (null for views that could not be linked); "
              "`sparse_homographies`: the synchronized feature-based estimate before the dense "
              "step; `failed_pairs`; per-round `history`.",
              "- `masks/mask_NNN.png`: the plane mask of image NNN in its own pixels "
              "(255 = on the dominant plane).",
              "- `mean_warped.png`: the mean of all images warped into the reference frame, on "
              "the reference image's own canvas (parts of views outside it are cut off). "
              "Sharp where the homographies agree, blurred where they do not; black where no "
              "warped image covers the canvas (outside every view's footprint)."]
    if stale:
        lines.append(f"- removed {len(stale)} mask file(s) of an earlier run into this folder "
                     f"(images beyond this run's {len(res.masks)}): "
                     f"{', '.join(p.name for p in stale[:5])}{' ...' if len(stale) > 5 else ''}")
    (out / "report.md").write_text("\n".join(lines) + "\n")
    return lines


def _unconverged_note(res) -> str:
    """Why the rounds stopped unconverged, and what to change (empty when they converged)."""
    hist = res.info.get("history") or []
    if res.converged or not hist:
        return ""
    return (f" (the corners still moved {hist[-1]['max_corner_change']:.3g} px in round "
            f"{hist[-1]['iteration']}, above the tolerance of "
            f"{res.info['options'].tol:g} px; --max-iter allows more rounds)")


def _stale_masks(folder: Path, n_images: int) -> list[Path]:
    """The ``mask_NNN.png`` files in ``folder`` (this command's own names) of image numbers
    ``>= n_images``: left by an earlier run on more images into the same ``--out``."""
    stale = []
    if not folder.is_dir():
        return stale
    for path in folder.iterdir():
        m = re.fullmatch(r"mask_([0-9]{3,})\.png", path.name)
        if (m and path.name == f"mask_{int(m.group(1)):03d}.png"     # a name this writes
                and int(m.group(1)) >= n_images and path.is_file()):
            stale.append(path)
    return sorted(stale)


def _dense_line(res, args) -> str:
    """What the dense step did: updates accepted / rejected / diverged over the rounds."""
    if args.no_dense:
        return "- dense refinement: off (--no-dense): the homographies are the sparse estimate"
    counts: dict[str, int] = {}
    for h in res.info.get("history", []):
        for rec in h.get("dense_views", {}).values():
            counts[rec["status"]] = counts.get(rec["status"], 0) + 1
    total = sum(counts.values())
    accepted = counts.get("accepted", 0)
    detail = ", ".join(f"{k.replace('_', ' ')} {v}" for k, v in sorted(counts.items()))
    if total == 0:
        return "- dense refinement: on, but no view was refined (no round ran)"
    if accepted == 0:
        return (f"- dense refinement: on, but every dense update was rejected ({detail}): the "
                "homographies are the sparse estimate")
    return f"- dense refinement: on; view updates over {res.n_iter} round(s): {detail}"


def _views_line(res, names) -> str:
    import numpy as np

    lost = [names[k] for k, H in enumerate(res.homographies) if not np.all(np.isfinite(H))]
    if not lost:
        return "- views linked to the reference: all"
    return (f"- views that could not be linked to the reference (no homography, empty mask): "
            f"{', '.join(lost)}")


def _imwrite(path: Path, image) -> None:
    import cv2

    if not cv2.imwrite(str(path), image):
        raise CLIError(f"cannot write {path}")


def add_parser(sub) -> None:
    """Register ``homography``."""
    p = sub.add_parser(
        "homography", help="homographies of the dominant plane across images, with plane masks")
    p.add_argument("images", nargs="+", metavar="IMAGE", help="image files (2 or more)")
    p.add_argument("--reference", type=int, default=0,
                   help="index of the reference image (its plane defines the homographies)")
    p.add_argument("--out", default="transync-homography",
                   help="output folder (created only when the run succeeds)")
    p.add_argument("--no-dense", action="store_true", help="skip the dense photometric step")
    p.add_argument("--no-segment", action="store_true", help="skip the plane segmentation")
    p.add_argument("--method", default="ransac", choices=RANSAC,
                   help="robust estimator of the pairwise homographies (OpenCV's)")
    p.add_argument("--threshold", type=positive_float, default=3.0,
                   help="RANSAC threshold (pixels)")
    p.add_argument("--features", type=int_at_least(1, maximum=10**6), default=2000,
                   help="SIFT features per image (at most 10**6)")
    p.add_argument("--max-iter", type=positive_int, default=3, help="segmentation + dense rounds")
    p.add_argument("--dense-target", default="auto", choices=["auto", "mean", "reference"],
                   help="what the dense step aligns each view to: the mean of the warped views, "
                        "the reference image, or auto (the mean from 4 views on)")
    p.add_argument("--seed", type=seed_int, default=0,
                   help="seed of the random stages (RANSAC, segmentation); same seed, same "
                        "answer")
    p.add_argument("--no-progress", action="store_true",
                   help="hide the stage log and the progress bar (shown on stderr by default)")
    p.add_argument("--verbose", action="store_true", help=argparse.SUPPRESS)   # the old opt-in
    p.set_defaults(func=_cmd_homography)
