"""``match_collection``: match N graphs at once and return cycle-consistent correspondences.

The driver reads as its stages: check the input, build the pair affinities, run the pairwise
stage (independent pairs, or the lock-step synchronized solvers), synchronize or run CAO, score
and package the result.
"""

from __future__ import annotations

import time
import warnings
from collections.abc import Mapping

import numpy as np

from .._blas import blas_limit
from .._validation import as_generator, check_array, check_choice, check_positive
from ..exceptions import ConvergenceWarning
from ..permutations import MultiMatching, cycle_inconsistency_arrays
from ..synchronization import synchronize_doubly_stochastic, synchronize_permutations
from ._affinity import PairAffinities, all_pairs, check_graphs, check_pairs
from ._cao import cao
from ..parallel import map_chunks, split_chunks
from ._lockstep import SOLVERS as LOCKSTEP_SOLVERS
from ._lockstep import doubly_stochastic_iterates, lockstep_options, round_blocks, run_lockstep
from ._refine import refine_consistent
from ._result import MultiMatchingResult

__all__ = ["match_collection", "SOLVERS", "ONLINE_SOLVERS", "CAO_VARIANTS", "SYNCS"]

ONLINE_SOLVERS = LOCKSTEP_SOLVERS
PAIRWISE_SOLVERS = ("rrwm", "ga", "pf", "sm", "ipfp")
CAO_VARIANTS = ("cao", "cao-c", "cao-uc", "cao-pc")
SOLVERS = PAIRWISE_SOLVERS + CAO_VARIANTS
SYNCS = ("birkhoff", "spectral", "orthogonal")
#: Frank-Wolfe iterations of one warm-started Birkhoff synchronization inside an online solver
SYNC_POINT_ITER = 5


def match_collection(graphs, *, solver: str = "rrwm", sync: str | None = "auto",
                     mode: str = "online", affinity=None, pairs=None, executor=None,
                     options: dict | None = None, sync_every: int | None = None,
                     damping: float = 1.0, refine: bool = True, rng=None,
                     progress: bool = True) -> MultiMatchingResult:
    """Match ``N`` graphs at once; synchronized methods return cycle-consistent maps.

    Methods (thesis ch. 6):

    * ``solver="ga" | "rrwm" | "pf"`` with ``sync="birkhoff"`` and ``mode="online"`` (default):
      S-GA, S-RRWM, S-PF. All pairs run in lock-step on batched ``(P, n, n)`` arrays; at each
      synchronization point (every ``sync_every`` outer steps: by default RRWM 5 iterations,
      GA 4 beta levels, PF 4 lambda steps) every pair's doubly-stochastic iterate is replaced by
      ``(1 - damping) X + damping Y``, ``Y`` the Birkhoff-polytope synchronization of all
      iterates (warm-started from the previous synchronization point), so that consistency
      steers the optimization. The output is the better (by total affinity score) of the most
      probable consistent configuration of the last synchronization and the permutation
      synchronization of the final per-pair roundings: cycle-consistent either way.
    * ``mode="offline"``: every pair solved on its own (``executor`` spreads the work), then one
      synchronization (``"birkhoff"`` on the soft solutions, ``"spectral"`` / ``"orthogonal"``
      on the rounded ones; ``sm`` and ``ipfp`` give 0/1 blocks). ``sm`` and ``ipfp`` are
      offline only.
    * ``sync=None``: plain pairwise matching of every pair (the unsynchronized baselines; RRWM is
      the lock-step solver's default variant, pygmtools', see ``options``).
    * ``solver="cao" | "cao-c" | "cao-uc" | "cao-pc"``: Yan et al.'s composition-based multi-graph
      matching (TPAMI 2016) started from pairwise RRWM on the same affinities; its output need
      not be consistent (``matching`` is ``None`` unless a ``sync`` is asked for on top; its
      maps are hard, so ``"birkhoff"`` there means the spectral permutation synchronization).

    Parameters
    ----------
    graphs : sequence of Graph
        At least two graphs, all with the same number ``n >= 1`` of nodes.
    solver : str, default="rrwm"
        One of :data:`SOLVERS`.
    sync : {"auto", "birkhoff", "spectral", "orthogonal", None}, default="auto"
        ``"auto"``: ``"birkhoff"`` for the pairwise solvers, ``None`` for CAO.
    mode : {"online", "offline"}, default="online"
        Ignored when ``sync`` is ``None`` (nothing to synchronize) and for CAO.
    affinity : callable, array or mapping, optional
        ``affinity(g_i, g_j) -> Affinity`` (a module-level function or ``functools.partial`` of
        one when a process-based ``executor`` is used); default
        :func:`~transync.matching.gaussian_edge_affinity` with ``sigma2=0.15``. Or precomputed
        pygmtools-layout ``K`` blocks: an ``(N, N, n*n, n*n)`` array, a dict ``{(i, j): K_ij}`` or
        an ``N x N`` nested list.
    pairs : array-like of shape (P, 2), optional
        The view graph: which pairs to match (default: all). Synchronization needs it connected;
        CAO needs all pairs.
    executor : None, "serial", "processes", int or Executor-like, optional
        Spreads the independent pairwise work (offline mode, CAO's pairwise stage): ``None`` /
        ``"serial"``, ``"processes"`` or ``n_jobs`` (joblib), or anything with ``submit`` (a
        ``concurrent.futures`` executor or a ``dask.distributed.Client``). The online solvers run
        all pairs in lock-step in this process and refuse an executor.
    options : dict, optional
        Options of the pairwise solver (:func:`transync.multigraph.run_lockstep` for rrwm, ga,
        pf; :func:`transync.matching.solver_options` for sm, ipfp); for CAO, of its pairwise
        RRWM. RRWM runs pygmtools' variant unless ``options={"variant": "original"}``.
    sync_every : int, optional
        Online solvers: outer steps between synchronization points (default RRWM 5 iterations,
        GA 4 beta levels, PF 4 lambda steps). Refused elsewhere.
    damping : float in (0, 1], default=1.0
        Online solvers: weight of the synchronized iterate at each synchronization point.
        Refused elsewhere.
    refine : bool, default=True
        After synchronization, re-anchor graphs on the pairwise stage's maps while the total
        affinity score increases (consistent coordinate ascent, see ``info["refine"]``); the output
        stays consistent and its total score never decreases. ``False``: the synchronization's
        configuration as is.
    rng : None, int or numpy.random.Generator
        Seeds the synchronization's eigensolvers and the sampled consistency report.
    progress : bool, default=True
        tqdm progress bars on the long loops.

    Returns
    -------
    MultiMatchingResult
        The pairwise assignments of every pair (cycle-consistent when synchronized, with the
        universe labels in ``matching``), per-pair and total affinity scores, input and output
        consistency, timings per stage.

    Raises
    ------
    ValueError, TypeError
        Fewer than two graphs, graphs of different sizes, unknown options, a bad view graph, a
        mis-shaped ``K`` collection, an executor with the online solvers.

    Warns
    -----
    ConvergenceWarning
        Once, when pairwise solvers stop at their iteration budget (and ``converged=False``).
        The online solvers are different: every synchronization point restarts the pairs'
        stopping tests, and on hard problems they run to the budget by design; they do not
        warn, and ``converged`` says whether every pair met its test after the last point.

    Examples
    --------
    >>> import functools
    >>> from transync import match_collection
    >>> from transync.datasets import make_graph_collection
    >>> from transync.matching import gaussian_edge_affinity
    >>> p = make_graph_collection(n_graphs=5, n_inliers=8, deformation=0.0, rng=0)
    >>> aff = functools.partial(gaussian_edge_affinity, sigma2=0.05)
    >>> res = match_collection(p.graphs, solver="rrwm", affinity=aff, progress=False)
    >>> res.accuracy(p.ground_truth), res.consistency
    (1.0, 1.0)
    """
    t_start = time.perf_counter()
    graphs = check_graphs(graphs)
    n = graphs[0].n_nodes
    N = len(graphs)
    solver, sync, mode = _check_method(solver, sync, mode)
    pairs = _check_pairs(pairs, N, need_all=solver in CAO_VARIANTS,
                         need_connected=sync is not None)
    online = mode == "online" and sync is not None and solver in ONLINE_SOLVERS
    if not online:
        mode = "offline"                 # the pairs are solved independently: as run
    damping = check_positive(damping, "damping")
    if damping > 1:
        raise ValueError(f"`damping` must be in (0, 1], got {damping}")
    for name, value, default in (("sync_every", sync_every, None), ("damping", damping, 1.0)):
        if not online and value != default:
            raise ValueError(f"`{name}` steers the online synchronized solvers; solver="
                             f"{solver!r} with sync={sync!r} runs none, got {name}={value!r}")
    if online and executor is not None:
        raise ValueError("`executor` spreads independent pairwise work (mode='offline', CAO); "
                         "the online solvers run all pairs in lock-step in this process: pass "
                         f"executor=None or mode='offline', got executor={executor!r}")
    if not isinstance(refine, (bool, np.bool_)):
        raise TypeError(f"`refine` must be True or False, got {refine!r}")
    if not isinstance(progress, (bool, np.bool_)):
        raise TypeError(f"`progress` must be True or False, got {progress!r}")
    options = _check_options(options, "rrwm" if solver in CAO_VARIANTS else solver)
    gen = as_generator(rng)
    with blas_limit(n * n):          # many small products: one BLAS thread is faster
        return _run(graphs, n, pairs, affinity, solver, sync, mode, executor, options,
                    sync_every, damping, refine, gen, progress, t_start)


def _run(graphs, n, pairs, affinity, solver, sync, mode, executor, options, sync_every, damping,
         refine, gen, progress, t_start) -> MultiMatchingResult:
    """The stages, in order (arguments checked by :func:`match_collection`)."""
    N = len(graphs)
    timings: dict[str, float] = {}
    info: dict = {}
    t = time.perf_counter()
    aff = _pair_affinities(graphs, pairs, affinity, n)
    timings["affinity"] = time.perf_counter() - t

    if solver in CAO_VARIANTS:
        stage = _cao_stage(aff, N, solver, options, executor, progress, timings, info)
    elif mode == "online" and sync is not None:
        stage = _online_stage(aff, N, n, solver, sync, options, sync_every, damping, gen,
                              progress, timings, info)
    else:
        stage = _offline_stage(aff, solver, options, executor, progress, timings)
    assignments, soft, n_iter, unconverged = stage
    if unconverged and mode == "offline":
        warnings.warn(f"match_collection: {unconverged} of {len(pairs)} pairs did not converge "
                      f"within the iteration budget of solver {solver!r} (see options "
                      "'max_iter'); their last iterates are used", ConvergenceWarning,
                      stacklevel=3)
    input_consistency = _consistency(pairs, info.pop("input_assignments", assignments), n, N,
                                     gen)

    matching = info.pop("matching", None)
    if sync is not None and matching is None:
        t = time.perf_counter()
        matching = _synchronize(pairs, assignments, soft, n, N, sync, gen)
        timings["sync"] = timings.get("sync", 0.0) + time.perf_counter() - t
    if matching is not None and refine:
        t = time.perf_counter()
        matching = _refine(matching, pairs, assignments, aff, info)
        timings["refine"] = time.perf_counter() - t
    if matching is not None:
        assignments = matching.pairwise_array(pairs)
        consistency = 1.0
    else:
        consistency = _consistency(pairs, assignments, n, N, gen)
    scores = aff.score_assignments(np.arange(len(pairs)), assignments)
    timings["total"] = time.perf_counter() - t_start
    return MultiMatchingResult(
        pairs=pairs, assignments=np.asarray(assignments, dtype=np.int64), matching=matching,
        scores=np.asarray(scores, dtype=float), total_score=float(np.sum(scores)),
        consistency=float(consistency), input_consistency=float(input_consistency),
        timings=timings, solver=solver, sync=sync, mode=mode, n_iter=int(n_iter),
        converged=not unconverged, n_graphs=N, info=info)


# --------------------------------------------------------------------------- checks


def _check_method(solver, sync, mode):
    solver = check_choice(solver, "solver", SOLVERS)
    mode = check_choice(mode, "mode", ("online", "offline"))
    if isinstance(sync, str) and sync == "auto":
        sync = None if solver in CAO_VARIANTS else "birkhoff"
    elif sync is not None:
        if not isinstance(sync, str) or sync not in SYNCS:
            raise ValueError(f"`sync` must be one of 'auto', {', '.join(map(repr, SYNCS))} or "
                             f"None, got {sync!r}")
    if (sync is not None and mode == "online" and solver not in ONLINE_SOLVERS
            and solver not in CAO_VARIANTS):
        raise ValueError(f"mode='online' synchronizes inside the solvers {ONLINE_SOLVERS}; "
                         f"solver={solver!r} runs offline only: pass mode='offline'")
    return solver, sync, mode


def _check_options(options, solver: str) -> dict:
    """The solver's keyword options; unknown names are refused by name, listing the valid ones."""
    if options is None:
        return {}
    if not isinstance(options, Mapping):
        raise TypeError(f"`options` must be a dict of solver options, got "
                        f"{type(options).__name__}")
    from ..matching import solver_options

    valid = lockstep_options(solver) if solver in ONLINE_SOLVERS else solver_options(solver)
    unknown = sorted(set(options) - set(valid))
    if unknown:
        raise TypeError(f"`options` has unknown option(s) {', '.join(map(repr, unknown))} for "
                        f"solver={solver!r}; valid: {', '.join(valid)}")
    return dict(options)


def _check_pairs(pairs, N: int, *, need_all: bool, need_connected: bool) -> np.ndarray:
    """The view graph as (P, 2) rows ``i < j`` (either order accepted), checked."""
    allp = all_pairs(N)
    if pairs is None:
        return allp
    arr = check_array(pairs, "pairs", dtype=None)
    if arr.ndim == 2 and arr.shape[1:] == (2,) and arr.size and arr.dtype.kind in "iuf":
        same = np.flatnonzero(arr[:, 0] == arr[:, 1])
        if same.size:
            raise ValueError(f"`pairs[{same[0]}]` pairs graph {arr[same[0], 0]} with itself")
        arr = np.sort(arr, axis=1)
    arr = check_pairs(arr, N)        # shape, integer indices in range, no repeated pair
    if need_all and len(arr) != len(allp):
        raise ValueError(f"CAO composes maps through every third graph and needs all "
                         f"{len(allp)} pairs of the {N} graphs; `pairs` has {len(arr)}")
    if need_connected:
        from scipy.sparse import coo_matrix
        from scipy.sparse.csgraph import connected_components

        A = coo_matrix((np.ones(len(arr)), (arr[:, 0], arr[:, 1])), shape=(N, N))
        n_comp, _ = connected_components(A, directed=False)
        if n_comp > 1:
            raise ValueError(f"`pairs` leaves the {N} graphs in {n_comp} disconnected groups; "
                             "synchronization needs a connected view graph (or use sync=None)")
    return arr


# --------------------------------------------------------------------------- stages


def _pair_affinities(graphs, pairs, affinity, n) -> PairAffinities:
    if affinity is None or callable(affinity):
        return PairAffinities.from_graphs(graphs, pairs, affinity)
    if isinstance(affinity, (Mapping, list, tuple, np.ndarray)):
        return PairAffinities.from_blocks(affinity, pairs, n, n_graphs=len(graphs),
                                          name="affinity")
    raise TypeError("`affinity` must be a callable (g_i, g_j) -> Affinity, pygmtools K blocks "
                    "((N, N, n*n, n*n) array, dict {(i, j): K} or nested list) or None, got "
                    f"{type(affinity).__name__}")


def _solve_chunk(payload):
    """Worker (module level, picklable): solve a chunk of independent pairs."""
    aff, solver, options = payload
    with warnings.catch_warnings():      # unconverged pairs are counted and reported once
        warnings.simplefilter("ignore", ConvergenceWarning)
        if solver in ONLINE_SOLVERS:
            out = run_lockstep(aff, solver=solver, sync=None, options=options, progress=False)
            return out.soft, out.assignments, out.n_iter, int(np.sum(~out.converged))
        from .. import matching

        fn = getattr(matching, solver)
        results = [fn(aff.pair(p), **(options or {})) for p in range(len(aff))]
    assign = np.stack([r.assignment for r in results])
    n2 = aff.n2
    soft = np.zeros((len(aff), aff.n1, n2))
    rows = np.arange(aff.n1)
    for p in range(len(aff)):
        ok = assign[p] >= 0
        soft[p, rows[ok], assign[p][ok]] = 1.0
    return (soft, assign, max(r.n_iter for r in results),
            sum(not r.converged for r in results))


def _offline_stage(aff, solver, options, executor, progress, timings):
    t = time.perf_counter()
    chunks = split_chunks(len(aff), executor)
    outs = map_chunks(_solve_chunk, [(aff.subset(idx), solver, options) for idx in chunks],
                      executor=executor, progress=progress, desc=f"{solver} pairs")
    order = np.concatenate(chunks)
    soft = np.empty((len(aff), aff.n1, aff.n2))
    assign = np.empty((len(aff), aff.n1), dtype=np.int64)
    soft[order] = np.concatenate([o[0] for o in outs])
    assign[order] = np.concatenate([o[1] for o in outs])
    timings["pairwise"] = time.perf_counter() - t
    return assign, soft, max(o[2] for o in outs), sum(o[3] for o in outs)


def _cao_stage(aff, N, variant, options, executor, progress, timings, info):
    assign, _, n_iter, unconverged = _offline_stage(aff, "rrwm", options, executor, progress,
                                                  timings)
    info["input_assignments"] = assign
    t = time.perf_counter()
    out = cao(assign, aff.pairs, N, aff.score_assignments, variant=variant, progress=progress)
    timings["cao"] = time.perf_counter() - t
    info["cao"] = {"n_iter": out.n_iter, "converged": out.converged, "history": out.history}
    return out.assignments, None, n_iter, unconverged


class _SyncPoint:
    """The online synchronization step: soft iterates ``(P, n, n)`` -> synchronized blocks."""

    def __init__(self, pairs, n, N, sync, gen):
        self.pairs, self.n, self.N, self.sync, self.gen = pairs, n, N, sync, gen
        self.last = None                 # last BirkhoffSyncResult (warm start) or matching
        self.first_rounding = None
        self.seconds = 0.0

    def __call__(self, X):
        t = time.perf_counter()
        if self.first_rounding is None:
            self.first_rounding = round_blocks(X)
        if self.sync == "birkhoff":
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", ConvergenceWarning)
                res = synchronize_doubly_stochastic(_by_pair(self.pairs, X), init=self.last,
                                                    max_iter=SYNC_POINT_ITER, rng=self.gen)
            self.last = res
            Y = res.stacked_blocks(self.pairs)
        else:
            m = _synchronize(self.pairs, round_blocks(X), None, self.n, self.N, self.sync,
                             self.gen)
            self.last = m
            Y = np.zeros_like(X)
            P = m.pairwise_array(self.pairs)
            Y[np.arange(len(P))[:, None], np.arange(self.n)[None, :], P] = 1.0
        self.seconds += time.perf_counter() - t
        return Y


def _online_stage(aff, N, n, solver, sync, options, sync_every, damping, gen, progress,
                  timings, info):
    point = _SyncPoint(aff.pairs, n, N, sync, gen)
    t = time.perf_counter()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ConvergenceWarning)
        out = run_lockstep(aff, solver=solver, sync=point, sync_every=sync_every,
                           damping=damping, options=options, progress=progress)
    timings["pairwise"] = time.perf_counter() - t - point.seconds
    first_rounding, seconds_at_points = point.first_rounding, point.seconds
    t = time.perf_counter()
    final = out.assignments          # the solvers' own rounding (as transync.matching's)
    method = "spectral" if sync == "birkhoff" else sync
    candidates = {"permutation_sync": _synchronize(aff.pairs, final, None, n, N, method, gen)}
    if sync == "birkhoff":
        point(doubly_stochastic_iterates(out.soft))     # one last warm-started synchronization
        candidates["map_atom"] = point.last.matching
    elif isinstance(point.last, MultiMatching):
        candidates["last_sync"] = point.last
    idx = np.arange(len(aff.pairs))
    scores = {k: float(np.sum(aff.score_assignments(idx, m.pairwise_array(aff.pairs))))
              for k, m in candidates.items()}
    best = max(scores, key=scores.get)
    timings["sync"] = seconds_at_points + time.perf_counter() - t
    info.update({"n_sync": out.n_sync, "output": best, "candidate_scores": scores,
                 "matching": candidates[best],
                 "input_assignments": first_rounding if first_rounding is not None else final})
    return final, out.soft, out.n_iter, int(np.sum(~out.converged))


def _refine(matching, pairs, proposals, aff, info) -> MultiMatching:
    """Consistent coordinate ascent from the synchronized configuration (module _refine)."""
    L = np.stack(matching.labels)
    if np.any(L < 0) or np.any(np.sort(L, axis=1) != np.arange(L.shape[1])):
        return matching                       # not a full configuration: nothing to re-anchor
    L, history = refine_consistent(L, pairs, np.asarray(proposals, dtype=np.int64),
                                   aff.score_assignments)
    info["refine"] = {"score_history": history, "sweeps": len(history) - 1}
    return MultiMatching(list(L), matching.n_universe)


def _by_pair(pairs, values) -> dict:
    """``{(i, j): values[p]}`` for ``pairs[p] = (i, j)``: the synchronizers' pairwise input."""
    return {(int(i), int(j)): values[p] for p, (i, j) in enumerate(pairs.tolist())}


def _synchronize(pairs, assignments, soft, n, N, sync, gen) -> MultiMatching:
    """One synchronization of the pairwise stage's output into universe labels."""
    if sync == "birkhoff" and soft is not None:
        soft = doubly_stochastic_iterates(soft)       # solver iterates are DS to ~1e-3 only
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", ConvergenceWarning)
            return synchronize_doubly_stochastic(_by_pair(pairs, soft), rng=gen).matching
    maps = _by_pair(pairs, assignments)
    method = "spectral" if sync in ("birkhoff", "spectral") else "orthogonal"
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ConvergenceWarning)
        return synchronize_permutations(maps, method=method, n_universe=n,
                                        sizes=[n] * N, rng=gen).matching


def _consistency(pairs, assignments, n, N, gen) -> float:
    if assignments is None or len(pairs) < 3:
        return 1.0
    rep = cycle_inconsistency_arrays(pairs, np.asarray(assignments), np.full(N, n), rng=gen)
    return 1.0 - float(rep["cycle_error"]) if rep["n_triangles"] else 1.0
