"""``transync match`` (two point sets), ``transync collection`` (many point sets, matched at once)
and ``transync sync`` (pairwise assignments as JSON)."""

from __future__ import annotations

import json
import math
import re
from pathlib import Path

from ._common import (CLIError, check_output_file, cli_message, emit, input_file,
                      positive_float, positive_int, seed_int)

__all__ = ["add_parsers", "read_points"]

#: match_collection's arguments that ``collection`` has as options (named so in its errors)
_COLLECTION_OPTIONS = ("n_universe", "verify_threshold", "verify", "solver", "sync", "mode",
                       "partial", "sigma2", "affinity", "edges", "seed")

METHODS = ("hungarian", "sinkhorn", "sm", "rrwm", "ipfp", "ga", "pf")
LINEAR = ("hungarian", "sinkhorn")
#: ``synchronize_permutations``'s methods (kept in step by tests/cli)
SYNC_METHODS = ("spectral", "orthogonal", "matcheig")
#: ``match_collection``'s solvers, synchronizations and partial modes (kept in step by tests/cli)
COLLECTION_SOLVERS = ("rrwm", "ga", "pf", "sm", "ipfp", "cao", "cao-c", "cao-uc", "cao-pc")
COLLECTION_SYNCS = ("birkhoff", "spectral", "orthogonal", "none")
PARTIAL = ("universe", "dummies")
#: ``gaussian_edge_affinity``'s default width (kept in step by tests/cli; the CLI does not import
#: the library to build its parser)
DEFAULT_SIGMA2 = 0.15


def read_points(path):
    """Points from ``.npy`` or a text/CSV file with one point a row, as a finite (n, d) array.

    Text files: numbers separated by commas or white space; blank lines and lines starting
    with ``#`` are skipped. Every error names the file (and the line for text files).
    """
    import numpy as np

    p = input_file(path, "a text/CSV or .npy file of points")
    if p.suffix.lower() == ".npy":
        try:
            pts = np.load(p, allow_pickle=False)
        except (ValueError, OSError, EOFError) as exc:
            raise CLIError(f"{path}: not a readable .npy array ({exc})") from exc
        if pts.dtype.kind not in "biuf":
            raise CLIError(f"{path}: expected a real numeric array, got dtype {pts.dtype}")
        if pts.ndim != 2:
            raise CLIError(f"{path}: expected an array of shape (n_points, dim), got shape "
                           f"{pts.shape}")
        pts = pts.astype(float)
        bad = np.flatnonzero(~np.isfinite(pts).all(axis=1))
        if bad.size:
            raise CLIError(f"{path}: coordinates must be finite, row {bad[0]} is "
                           f"{pts[bad[0]].tolist()}")
    else:
        pts = _read_text_points(p)
    if pts.shape[0] == 0:
        raise CLIError(f"{path}: no points found (empty file)")
    if pts.shape[1] == 0:
        raise CLIError(f"{path}: points have no coordinates")
    return pts


def _read_text_points(p: Path):
    import numpy as np

    raw = p.read_bytes()
    try:
        if b"\0" in raw:
            raise UnicodeDecodeError("ascii", raw, 0, 1, "NUL byte")
        text = raw.decode("utf-8-sig")                  # a byte-order mark is allowed
    except UnicodeDecodeError:
        raise CLIError(f"{p}: not a text file of points (binary content); give a .npy file or "
                       "text/CSV with one point a row") from None
    rows, dim, first = [], None, None
    for lineno, line in enumerate(text.splitlines(), start=1):
        s = line.strip()
        if not s or s.startswith("#"):
            continue
        # commas or semicolons separate fields (white space around them allowed), else white
        # space; an empty field ("1,,2", "1,2,") is refused, not skipped
        if "," in s or ";" in s:
            fields = [f.strip() for f in re.split(r"[,;]", s)]
            if "" in fields:
                raise CLIError(f"{p}, line {lineno}: empty field in {s[:60]!r} (two separators "
                               "in a row, or one at the start or end)")
        else:
            fields = s.split()
        try:
            row = [float(f) for f in fields]
        except ValueError:
            raise CLIError(f"{p}, line {lineno}: expected numbers, got {s[:60]!r}"
                           + (" (remove the header line)" if not rows else "")) from None
        if not all(math.isfinite(v) for v in row):
            raise CLIError(f"{p}, line {lineno}: coordinates must be finite, got {s[:60]!r}")
        if dim is None:
            dim, first = len(row), lineno
        elif len(row) != dim:
            raise CLIError(f"{p}, line {lineno}: expected {dim} coordinates (as on line "
                           f"{first}), got {len(row)}")
        rows.append(row)
    return np.array(rows, dtype=float).reshape(len(rows), dim or 0)


def _point_scale(named_sets) -> float:
    """The one factor every point set is divided by: the largest coordinate range (1 when every
    point is the same). A range beyond float64 (points at +-1e308) is refused, naming the file:
    it made the factor inf and every point 0, and wrote ``Infinity`` into the JSON."""
    import numpy as np

    scale = 0.0
    for path, P in named_sets:
        if P.size:
            with np.errstate(over="ignore"):
                span = float(np.ptp(P, axis=0).max())
            if not np.isfinite(span):
                raise CLIError(f"{path}: the coordinates span more than the largest float "
                               f"(from {float(P.min()):.3g} to {float(P.max()):.3g}); rescale "
                               "them")
            scale = max(scale, span)
    return scale if scale > 0 else 1.0       # every point identical: nothing to rescale


def _cmd_match(args) -> int:
    import numpy as np

    from ..exceptions import DegenerateInputError
    from ..graphs import Graph
    from ..matching import gaussian_edge_affinity, match_graphs

    check_output_file(args.out, [args.points1, args.points2])
    P1, P2 = read_points(args.points1), read_points(args.points2)
    if P1.shape[1] != P2.shape[1]:
        raise CLIError(f"the point sets have different dimensions: {args.points1} has "
                       f"{P1.shape[1]} coordinates a point, {args.points2} has {P2.shape[1]}")
    scale = _point_scale([(args.points1, P1), (args.points2, P2)])
    graphs = []
    for path, P in ((args.points1, P1), (args.points2, P2)):
        try:
            graphs.append(Graph.from_points(P / scale, edges=args.edges))
        except ValueError as exc:
            raise CLIError(f"{path}: {cli_message(exc, ('edges',))}") from exc
    g1, g2 = graphs
    if min(len(P1), len(P2)) < 2:
        raise CLIError(f"need at least 2 points in each set to compare edges, got {len(P1)} and "
                       f"{len(P2)}")
    try:
        aff = gaussian_edge_affinity(g1, g2, sigma2=args.sigma2)
    except DegenerateInputError:        # every edge pair's affinity underflows
        aff = None
    # first-order linearization of the edge affinity, (K 1)[i, a]: how well the edges around
    # i and a agree. All zero: every solver would return an arbitrary assignment.
    linear = None if aff is None else aff.matvec(np.ones((aff.n1, aff.n2)))
    top = float(linear.max()) if linear is not None and linear.size else 0.0
    if not top > 0:
        raise CLIError(f"the edge affinity is zero for every candidate pair (no edges, or "
                       f"--sigma2 {args.sigma2} too small for these point sets); increase "
                       "--sigma2 or use --edges full")
    unary = None
    if args.method in LINEAR:
        # point sets carry no node attributes: the linear solvers get the linearization, scaled
        # to a maximum of 1, as their unary term -- as in `transync experiment pairwise`
        unary = linear / top
    res = match_graphs(g1, g2, method=args.method, affinity=aff, node_affinity=unary)
    payload = {"method": args.method, "assignment": np.asarray(res.assignment).tolist(),
               "objective": float(res.objective), "n_iter": int(res.n_iter),
               "converged": bool(res.converged), "edges": args.edges, "sigma2": args.sigma2,
               "coordinate_scale": scale}
    if unary is not None:
        payload["unary"] = "first-order linearization of the edge affinity"
    return emit(payload, args.out)


def _cmd_collection(args) -> int:
    import functools

    import numpy as np

    from ..graphs import Graph
    from ..matching import gaussian_edge_affinity
    from ..multigraph import match_collection

    if len(args.points) < 2:
        raise CLIError(f"need at least 2 point sets to match, got {len(args.points)}")
    check_output_file(args.out, args.points)
    sets = [read_points(p) for p in args.points]
    dims = {P.shape[1] for P in sets}
    if len(dims) > 1:
        raise CLIError("the point sets have different dimensions: " + ", ".join(
            f"{p} has {P.shape[1]}" for p, P in zip(args.points, sets)))
    scale = _point_scale(list(zip(args.points, sets)))
    graphs = []
    for path, P in zip(args.points, sets):
        try:
            graphs.append(Graph.from_points(P / scale, edges=args.edges,
                                            k=min(5, max(len(P) - 1, 1))))
        except ValueError as exc:
            raise CLIError(f"{path}: {cli_message(exc, ('edges',))}") from exc
    if args.affinity == "length+angle":
        if sets[0].shape[1] != 2:
            raise CLIError(f"--affinity length+angle needs 2-d points, got {sets[0].shape[1]}-d")
        aff = functools.partial(gaussian_edge_affinity, attribute="length+angle",
                                sigma2=args.sigma2)
    else:
        aff = functools.partial(gaussian_edge_affinity, sigma2=args.sigma2)
    sync = None if args.sync == "none" else args.sync
    try:
        res = match_collection(graphs, solver=args.solver, sync=sync, mode=args.mode,
                               affinity=aff, n_universe=args.n_universe, partial=args.partial,
                               verify=None if args.verify == "none" else args.verify,
                               verify_threshold=args.verify_threshold,
                               rng=args.seed, progress=not args.quiet)
    except (ValueError, TypeError) as exc:
        raise CLIError(cli_message(exc, _COLLECTION_OPTIONS)) from exc
    payload = {
        "files": [str(p) for p in args.points], "sizes": res.sizes.tolist(),
        "solver": res.solver, "sync": res.sync, "mode": res.mode, "partial": args.partial,
        "n_universe": res.n_universe, "n_universe_rule": res.info.get("n_universe_rule"),
        "labels": (None if res.matching is None
                   else [np.asarray(lab).tolist() for lab in res.matching.labels]),
        "pairs": [[int(i), int(j), res.pairwise(int(i), int(j)).tolist()]
                  for i, j in res.pairs],
        "total_score": res.total_score, "consistency": res.consistency,
        "input_consistency": res.input_consistency, "converged": res.converged,
        "timings": {k: round(float(v), 4) for k, v in res.timings.items()},
        "edges": args.edges, "affinity": args.affinity, "sigma2": args.sigma2,
        "coordinate_scale": scale, "verify": args.verify,
        "verified_pairs": (None if "verify" not in res.info
                           else int(np.sum(res.info["verify"]["verified"]))),
        "verification_used": res.info.get("verify", {}).get("used", False),
    }
    return emit(payload, args.out)


def _read_pairs(path: str) -> tuple[dict, list | None]:
    """The pairwise maps ``{(i, j): assignment}`` of a sync JSON file and its optional
    ``"sizes"``."""
    import numpy as np

    p = input_file(path, "a JSON file {\"pairs\": ...}")
    try:
        data = json.loads(p.read_text(encoding="utf-8-sig"))    # a byte-order mark is allowed
    except UnicodeDecodeError:
        raise CLIError(f"{path}: not a JSON text file") from None
    except json.JSONDecodeError as exc:
        raise CLIError(f"{path}, line {exc.lineno}: not valid JSON ({exc.msg})") from None
    except RecursionError:
        raise CLIError(f"{path}: JSON nested too deeply to read (expected "
                       f"{{\"pairs\": [[i, j, assignment], ...]}})") from None
    form = '{"pairs": [[i, j, assignment or 0/1 matrix], ...]}'
    if not isinstance(data, dict) or "pairs" not in data:
        got = f"an object with keys {sorted(data)}" if isinstance(data, dict) else \
            type(data).__name__
        raise CLIError(f"{path}: expected a JSON object {form}, got {got}")
    entries = data["pairs"]
    if not isinstance(entries, list) or not entries:
        raise CLIError(f"{path}: \"pairs\" must be a non-empty list {form}")
    pairs = {}
    for k, entry in enumerate(entries):
        def ints(v):                        # integers within int64
            return isinstance(v, list) and all(
                isinstance(x, int) and not isinstance(x, bool) and -2**63 <= x < 2**63
                for x in v)

        ok = (isinstance(entry, list) and len(entry) == 3 and ints(entry[:2])
              and (ints(entry[2]) or (isinstance(entry[2], list) and entry[2]
                                      and all(ints(row) for row in entry[2])
                                      and len({len(row) for row in entry[2]}) == 1)))
        if not ok:
            raise CLIError(f"{path}: pairs[{k}] must be [i, j, map] with integers i, j and, as "
                           "the map, an assignment (a list of integers, -1 = unmatched) or a 0/1 "
                           f"matrix (a list of equal-length integer rows), all within int64, got "
                           f"{json.dumps(entry)[:80]}")
        i, j, a = entry
        if (i, j) in pairs:
            raise CLIError(f"{path}: pairs[{k}] repeats the pair ({i}, {j})")
        pairs[(i, j)] = np.asarray(a, dtype=np.int64)
    sizes = data.get("sizes")
    if sizes is not None and not (isinstance(sizes, list) and all(
            isinstance(n, int) and not isinstance(n, bool) and 1 <= n < 2**62 for n in sizes)):
        raise CLIError(f"{path}: \"sizes\" must be a list of node counts (integers >= 1), one "
                       f"per object, got {json.dumps(sizes)[:80]}")
    return pairs, sizes


def _cmd_sync(args) -> int:
    import numpy as np

    from ..synchronization import synchronize_permutations

    check_output_file(args.out, [args.pairwise])
    pairs, sizes = _read_pairs(args.pairwise)
    try:
        res = synchronize_permutations(pairs, method=args.method, n_universe=args.n_universe,
                                       sizes=sizes, rng=args.seed)
    except (ValueError, TypeError) as exc:
        msg = cli_message(exc, ("n_universe", "method")).replace(
            "pass `sizes=`", 'give "sizes": [n_0, n_1, ...] in the JSON').replace(
            "`sizes`", '"sizes"')
        raise CLIError(f"{args.pairwise}: {msg}") from exc
    payload = {"method": args.method, "labels": [np.asarray(lab).tolist() for lab in res.labels],
               "objective": float(res.objective), "converged": bool(res.converged),
               "n_iter": int(res.n_iter)}
    info = {k: v for k, v in res.info.items() if isinstance(v, (int, float, str, bool))}
    payload["info"] = info
    return emit(payload, args.out)


def add_parsers(sub) -> None:
    """Register ``match``, ``collection`` and ``sync``."""
    p = sub.add_parser("match", help="match two point sets (.npy, .txt or .csv, one point a row)")
    p.add_argument("points1", help="first point set: .npy, or .txt/.csv with one point (x y [z]) "
                                    "a row, no header line (blank lines and lines starting "
                                    "with # are skipped)")
    p.add_argument("points2", help="second point set, same format and dimension")
    p.add_argument("--method", default="rrwm", choices=list(METHODS),
                   help="solver; hungarian and sinkhorn use the linearized edge affinity as "
                        "their unary term")
    p.add_argument("--edges", default="full", choices=["full", "delaunay", "knn"],
                   help="graph built on each point set: complete, Delaunay triangulation, or "
                        "k nearest neighbours")
    p.add_argument("--sigma2", type=positive_float, default=DEFAULT_SIGMA2,
                   help="width of the Gaussian edge-length affinity exp(-(d1 - d2)^2 / sigma2), "
                        "after scaling both point sets to unit size (the library's value)")
    p.add_argument("--out", help="JSON output file (default: print)")
    p.set_defaults(func=_cmd_match)

    p = sub.add_parser(
        "collection", help="match many point sets at once (of any sizes): cycle-consistent maps "
                           "through a universe of nodes",
        description="Build a graph on every point set (all scaled by one factor), match all "
                    "pairs with transync.match_collection and print (or write) the universe "
                    "labels of every point and the map of every pair as JSON (-1 = unmatched).")
    p.add_argument("points", nargs="+", help="two or more point sets: .npy, or .txt/.csv with "
                                             "one point a row (sets may differ in size)")
    p.add_argument("--solver", default="rrwm", choices=list(COLLECTION_SOLVERS),
                   help="pairwise solver (rrwm, ga, pf: online synchronized by default; sm, "
                        "ipfp: with --mode offline) or CAO")
    p.add_argument("--sync", default="birkhoff", choices=list(COLLECTION_SYNCS),
                   help="synchronization; none: plain pairwise matching (CAO: use none)")
    p.add_argument("--mode", default="online", choices=["online", "offline"],
                   help="online: synchronization steers the lock-step solvers; offline: solve "
                        "every pair, then synchronize once")
    p.add_argument("--n-universe", type=positive_int, default=None,
                   help="universe size (default: estimated; the number of points when all sets "
                        "have the same size, unless --verify names a model)")
    p.add_argument("--partial", default="universe", choices=list(PARTIAL),
                   help="point sets of different sizes: map them into the universe, or pad "
                        "them with dummy nodes (the baseline)")
    p.add_argument("--edges", default="delaunay", choices=["full", "delaunay", "knn"],
                   help="graph on each point set: complete, Delaunay triangulation, or k = 5 "
                        "nearest neighbours")
    p.add_argument("--affinity", default="length", choices=["length", "length+angle"],
                   help="edge attribute of the Gaussian edge affinity (length+angle: 2-d points)")
    p.add_argument("--sigma2", type=positive_float, default=0.05,
                   help="width of the Gaussian edge affinity, after scaling all point sets by "
                        "one factor to unit size")
    p.add_argument("--verify", default="auto",
                   choices=["auto", "none", "affine", "similarity", "homography"],
                   help="geometric verification of every pair's matches before the "
                        "synchronization (2-d points of one rigid or planar object); auto: "
                        "for point sets of different sizes each pair keeps the better "
                        "supported of an affine map and a homography, kept when at least "
                        "70 %% of the pairs verify affinely; none for equal sizes")
    p.add_argument("--verify-threshold", type=positive_float, default=None,
                   help="verification gate, as a fraction of the median nearest-neighbour "
                        "distance of the points (default 0.5)")
    p.add_argument("--seed", type=seed_int, default=0, help="seed of the randomized steps")
    p.add_argument("--no-progress", "--quiet", dest="quiet", action="store_true",
                   help="hide the progress bars")
    p.add_argument("--out", help="JSON output file (default: print)")
    p.set_defaults(func=_cmd_collection)

    p = sub.add_parser("sync", help="synchronize pairwise assignments given as JSON "
                                    "{\"pairs\": [[i, j, assignment], ...]}")
    p.add_argument("pairwise", help="JSON file {\"pairs\": [[i, j, assignment], ...]} "
                                    "(assignment[u] = v, -1 unmatched) or 0/1 matrices; "
                                    "optionally \"sizes\": [n_0, n_1, ...], the node count "
                                    "of every object (needed when an object's nodes are never "
                                    "matched or it is in no pair)")
    p.add_argument("--method", default="spectral", choices=list(SYNC_METHODS),
                   help="permutation synchronization method (transync.synchronize_permutations)")
    p.add_argument("--n-universe", type=positive_int, default=None,
                   help="size of the universe of nodes (default: estimated from the spectrum; "
                        "the number of nodes when every object has the same size and every "
                        "map is a full permutation)")
    p.add_argument("--seed", type=seed_int, default=0,
                   help="seed of the randomized steps (the eigensolver's start above 2000 "
                        "nodes)")
    p.add_argument("--out", help="JSON output file (default: print)")
    p.set_defaults(func=_cmd_sync)
