"""``match_collection``: match N graphs at once and return cycle-consistent correspondences.

The driver reads as its stages: check the input, build the pair affinities, run the pairwise
stage (independent pairs, or the lock-step synchronized solvers), synchronize or run CAO, score
and package the result.
"""

from __future__ import annotations

import time
import warnings
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from .._blas import blas_limit
from .._validation import (as_generator, check_affinity_scale, check_array, check_bool,
                           check_choice, check_choices, check_index_pairs, check_int,
                           check_positive)
from ..exceptions import ConvergenceWarning
from ..permutations import MultiMatching, cycle_inconsistency_arrays
from ..synchronization import (
    estimate_universe,
    synchronize_doubly_stochastic,
    synchronize_permutations,
)
from ._affinity import PairAffinities, all_pairs, check_graphs, check_pairs
from ._cao import cao
from ..parallel import is_serial, map_chunks, split_chunks
from ._lockstep import SOLVERS as LOCKSTEP_SOLVERS
from ._lockstep import doubly_stochastic_iterates, lockstep_options, round_blocks, run_lockstep
from ._refine import refine_consistent
from ._result import MultiMatchingResult

__all__ = ["match_collection", "SOLVERS", "ONLINE_SOLVERS", "CAO_VARIANTS", "SYNCS", "PARTIAL"]

ONLINE_SOLVERS = LOCKSTEP_SOLVERS
PAIRWISE_SOLVERS = ("rrwm", "ga", "pf", "sm", "ipfp")
CAO_VARIANTS = ("cao", "cao-c", "cao-uc", "cao-pc")
SOLVERS = PAIRWISE_SOLVERS + CAO_VARIANTS
SYNCS = ("birkhoff", "spectral", "orthogonal")
#: how graphs of different sizes (or a universe larger than the graphs) are matched
PARTIAL = ("universe", "dummies")
#: Frank-Wolfe iterations of one warm-started Birkhoff synchronization inside an online solver
SYNC_POINT_ITER = 5
#: projected-power sweeps after the spectral permutation synchronization into a universe
UNIVERSE_REFINE = 20
#: after a geometric verification, a node keeps its slot only when at least one verified match
#: agrees with it (``synchronize_permutations(min_score=...)``): no verified evidence, no partner
VERIFY_MIN_SCORE = 1e-9
#: up to this many nodes in all, a universe size to estimate comes from the pairwise stage's
#: soft solutions (one dense eigenproblem of that size); above, from its rounded maps
SOFT_UNIVERSE_MAX = 2000
#: ``verify="auto"``: the plane models it verifies with (graphs of different sizes with 2-d
#: points), each pair keeping the better supported (``verify_assignment(model=...)``). Measured
#: (docs/methods/subgraphs.md): against the affine model alone, mean F1 +0.002 .. +0.017 on
#: CMU House partial (6-20 frames; level on the stored CMU point), +0.008 .. +0.068 on
#: generated perspective sequences, -0.002 on exact similarity views
AUTO_VERIFY_MODEL = ("affine", "homography")
#: ``verify="auto"``: below this share of pairs verified by the first (affine) model the
#: collection is not taken for views of one rigid or planar scene, and the unverified
#: pipeline's output is kept. Measured
#: (benchmarks/verify_auto.py, docs/methods/subgraphs.md): CMU House partial verifies 0.67-1.0
#: of its pairs on 6 frames over the whole sequence, 0.93-1.0 on 20, and gains 0.09-0.31 F1;
#: point sets jittered non-rigidly by half their spacing verify 0.40-0.67 and lose 0.06-0.29
AUTO_VERIFY_MIN_SHARE = 0.7


def match_collection(graphs, *, solver: str = "rrwm", sync: str | None = "auto",
                     mode: str = "online", affinity=None, pairs=None, executor=None,
                     options: dict | None = None, sync_every: int | None = None,
                     damping: float = 1.0, refine: bool = True, n_universe: int | None = None,
                     partial: str = "universe",
                     verify: str | tuple[str, ...] | None = "auto",
                     verify_threshold: float | None = None, rng=None,
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

    Graphs of different sizes, outliers (thesis ch. 7): with ``partial="universe"`` (default) every
    graph maps into a universe of ``d = n_universe`` slots (estimated by the synchronization when
    ``None``: ``res.n_universe``, rule in ``res.info["n_universe_rule"]``), each node to at most
    one slot and each slot to at most one node of a graph; the pairwise solvers run with slack
    (pairs padded internally to the largest graph with zero-affinity dummies, which never reach
    the output: a node matched to a dummy is unmatched, ``-1``), and the synchronization works on
    partial permutations (offline) or, online, on the multi-simplex (sub-doubly-stochastic real
    blocks; the dummies' rows and columns carry the slack between synchronization points).
    ``partial="dummies"`` is the thesis's baseline: every graph padded to ``d`` (default the
    largest size) with isolated dummy nodes, the full-permutation method run on the padded
    graphs, matches involving dummies dropped. With equal sizes and ``n_universe`` ``None`` or
    ``n`` both are the full-permutation method.

    Geometric verification (``verify=``, graphs with 2-d points, e.g. keypoints or landmarks):
    between the pairwise stage and the synchronization, every pair's map goes through
    :func:`~transync.matching.verify_assignment`: a RANSAC fit of one plane transform to its
    matches, guided matching within ``verify_threshold`` times the typical point spacing, a
    refit. Matches the geometry does not support are dropped (a pair that no transform
    explains keeps no match, nor one explained only by a transform that mirrors the plane:
    views are not mirror images), matches it predicts are added; the permutation synchronization
    (``"spectral"`` for ``sync="birkhoff"``: the verified maps are hard) then makes the
    verified maps consistent (with ``sync=None``, CAO's default, the verified maps are the
    output, not consistent). The quadratic objective prefers matching every node, so with
    graphs that share only part of their nodes its extra matches pull true ones away; the
    geometry does not (CMU House, 20 frames keeping 20-25 of 30 landmarks each: F1 0.77 ->
    0.99, ``docs/experiments/subgraph``). For rigid or planar scenes; deformable objects need a
    wider gate or none. With ``verify`` the consistent refinement (``refine``) is skipped (it
    climbs the quadratic score the verification overrides), the universe size is estimated
    unless ``n_universe`` is given, graphs of equal size included (the online solvers then run
    as for graphs of different sizes: a universe estimated from an unsynchronized pre-run), a
    pair that failed its verification counts as unobserved when the universe is estimated, and
    a node whose slot no verified match supports is left unplaced (label ``-1``, unmatched in
    every pair) instead of given an arbitrary partner. By default (``verify="auto"``) graphs of
    different sizes with 2-d points are verified, every pair keeping the better supported of an
    affine map and a homography, and the verification is dropped again when fewer than 70 % of
    the pairs pass with the affine map (not one rigid or planar scene: the output is then
    exactly ``verify=None``'s); equal sizes are not verified (there the quadratic model alone
    is exact on CMU House, and one affine map between far views costs up to 0.09 F1:
    ``docs/methods/subgraphs.md``).

    Parameters
    ----------
    graphs : sequence of Graph
        At least two graphs of ``n_i >= 1`` nodes each (a one-node graph is matched).
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
        an ``N x N`` nested list (graphs of different sizes: a dict or list of ``(n_i n_j, n_i
        n_j)`` blocks).
    pairs : array-like of shape (P, 2), optional
        The view graph: which pairs to match (default: all). Synchronization needs it connected;
        CAO needs all pairs.
    executor : None, "serial", "processes", int or Executor-like, optional
        Spreads the independent pairwise work (offline mode, CAO's pairwise stage, the offline
        geometric verification; the result does not depend on it): ``None`` /
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
        After synchronization, re-anchor graphs on the pairwise stage's maps and swap the
        universe slots of two nodes of a graph while the total affinity score increases
        (consistent coordinate ascent, described in the multi-graph guide; moves and scores in
        ``info["refine"]``); the output stays consistent and its total score never decreases.
        ``False``: the synchronization's configuration as is. Applies to full permutations
        (equal sizes, or ``partial="dummies"``).
    n_universe : int, optional
        Universe size ``d``, ``max n_i <= d <= sum n_i``; ``None``: ``n`` for graphs of equal
        size ``n``, else estimated by the synchronization (eigengap rule; with a view graph
        that leaves pairs out, the slots an orthogonal synchronization uses, see
        :func:`~transync.synchronize_permutations`).
    partial : {"universe", "dummies"}, default="universe"
        How graphs of different sizes (or ``d > n``) are matched (see above). CAO composes full
        permutations and needs ``"dummies"`` there.
    verify : {"auto", "affine", "similarity", "homography"}, tuple of them, or None, \
default="auto"
        Geometric verification of the pairwise maps (see above; every graph needs 2-d
        ``points``); not with ``partial="dummies"`` on graphs of different sizes (dummy nodes
        have no points). A tuple of models, e.g. ``("affine", "homography")``: each pair keeps
        the verified model with the most matches (ties: the earlier;
        :func:`~transync.matching.verify_assignment`). ``"auto"``: ``("affine",
        "homography")`` when the graphs are partial views of a universe (different sizes, or
        ``n_universe`` above their size, with ``partial="universe"``) and every graph has 2-d
        points, kept only when at least 70 % of the pairs verify with the first model, the
        affine map (otherwise, or when the points are beyond what
        :func:`~transync.matching.verify_assignment` takes, the unverified pipeline's output
        is returned, exactly as with ``None``); no verification otherwise. ``None``: never.
        ``res.info["verify"]``, when one ran: each pair's number of inliers, whether it
        verified (``"verified"``; with the first model alone: ``"verified_first"``, exactly
        what ``verify=<first model>`` verifies), the model it kept (``"pair_models"``; the
        first model where none verified or the points were refused), ``"auto"``, whether the
        verified maps were ``"used"`` and, when the points were refused under ``"auto"``,
        the reason (``"refused"``).
    verify_threshold : float, optional
        The verification's gate, as a fraction of the median nearest-neighbour distance among
        the second graph's points; default that of
        :func:`~transync.matching.verify_assignment` (0.5).
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
        Fewer than two graphs, a graph without nodes, unknown options, a bad view graph, a
        mis-shaped ``K`` collection, an executor with the online solvers, ``n_universe`` not an
        integer in ``[max n_i, sum n_i]``, CAO on graphs of different sizes with
        ``partial="universe"``, one ``(N, N, n*n, n*n)`` array with graphs of different sizes,
        ``verify`` on graphs without 2-d points or with the dummy-node baseline.

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

    Graphs of different sizes (each keeps part of a universe of 8 nodes):

    >>> from transync.datasets import make_subgraph_collection
    >>> c = make_subgraph_collection(n_graphs=4, n_universe=8, p_keep=(0.6, 1.0), rng=0)
    >>> res = match_collection(c.graphs, affinity=aff, progress=False)
    >>> res.sizes.tolist(), res.n_universe, res.accuracy(c.ground_truth)
    ([6, 7, 7, 8], 8, 1.0)
    """
    t_start = time.perf_counter()
    graphs = check_graphs(graphs, equal_sizes=False)
    N = len(graphs)
    solver, sync, mode = _check_method(solver, sync, mode)
    layout = _check_layout(graphs, n_universe, partial, solver, affinity)
    n = layout.n_pad
    pairs = _check_pairs(pairs, N, need_all=solver in CAO_VARIANTS,
                         need_connected=sync is not None)
    online = mode == "online" and sync is not None and solver in ONLINE_SOLVERS
    asked = f"solver={solver!r} with sync={sync!r} and mode={mode!r}"
    if not online:
        mode = "offline"                 # the pairs are solved independently: as run
    damping = check_positive(damping, "damping")
    if damping > 1:
        raise ValueError(f"`damping` must be in (0, 1], got {damping}")
    for name, value, default in (("sync_every", sync_every, None), ("damping", damping, 1.0)):
        if not online and value != default:
            raise ValueError(f"`{name}` steers the online synchronized solvers; {asked} "
                             f"runs none, got {name}={value!r}")
    if online and not is_serial(executor):   # None, "serial" and 1: in this process
        raise ValueError("`executor` spreads independent pairwise work (mode='offline', CAO); "
                         "the online solvers run all pairs in lock-step in this process: pass "
                         f"executor=None or mode='offline', got executor={executor!r}")
    if sync is None and n_universe is not None and layout.kind == "universe":
        # validated, then unused: the result had no universe (with partial="dummies" it sizes
        # the padding, and is used)
        raise ValueError(f"`n_universe` sizes the synchronized universe; {asked} synchronizes "
                         f"nothing, got n_universe={n_universe!r} (partial='dummies' pads every "
                         "graph to it)")
    refine = check_bool(refine, "refine")
    progress = check_bool(progress, "progress")
    options = _check_options(options, "rrwm" if solver in CAO_VARIANTS else solver)
    verify = _check_verify(verify, verify_threshold, graphs, layout)
    if verify is not None and layout.kind == "full" and n_universe is None:
        # verified maps are partial (unsupported nodes unmatched): the universe is estimated,
        # not forced to n, so that a node no verified match links keeps a slot of its own
        layout = _Layout(layout.sizes, layout.n_pad, "universe", None)
    gen = as_generator(rng)
    with blas_limit(n * n):          # many small products: one BLAS thread is faster
        return _run(graphs, layout, pairs, affinity, solver, sync, mode, executor, options,
                    sync_every, damping, refine, verify, gen, progress, t_start)


def _run(graphs, lay, pairs, affinity, solver, sync, mode, executor, options, sync_every,
         damping, refine, verify, gen, progress, t_start) -> MultiMatchingResult:
    """The stages, in order (arguments checked by :func:`match_collection`).

    The pairwise stage runs at ``lay.n_pad`` nodes; with ``lay.kind == "universe"`` its maps are
    stripped of the dummies before anything else sees them, with ``"dummies"`` the whole method
    runs on the padded graphs and the dummies are dropped from its output at the end.
    """
    N = len(graphs)
    timings: dict[str, float] = {}
    info: dict = {}
    t = time.perf_counter()
    aff = _pair_affinities(graphs, pairs, affinity, lay.n_pad)
    timings["affinity"] = time.perf_counter() - t

    if solver in CAO_VARIANTS:
        stage = _cao_stage(aff, N, solver, options, executor, progress, timings, info)
    elif mode == "online" and sync is not None:
        stage = _online_stage(aff, N, lay, solver, sync, options, sync_every, damping, gen,
                              progress, timings, info, build_output=verify is None)
    else:
        stage = _offline_stage(aff, solver, options, executor, progress, timings)
    assignments, soft, n_iter, unconverged = stage
    if unconverged and (mode == "offline" or solver in CAO_VARIANTS):
        # GA's budget is its inner loop per temperature; CAO's pairwise stage is RRWM
        which = f"CAO's pairwise RRWM (solver={solver!r})" if solver in CAO_VARIANTS \
            else f"solver {solver!r}"
        budget = "max_inner" if solver == "ga" else "max_iter"
        warnings.warn(f"match_collection: {unconverged} of {len(pairs)} pairs did not converge "
                      f"within the iteration budget of {which} (option {budget!r} of "
                      f"`options`); their last iterates are used", ConvergenceWarning,
                      stacklevel=3)
    if soft is not None:
        info["soft"] = _real_blocks(doubly_stochastic_iterates(soft), pairs, lay.sizes)
    assignments = lay.strip(pairs, assignments)
    input_assignments = lay.strip(pairs, info.pop("input_assignments", assignments))
    # verify="auto" may drop the verification again and must then return what verify=None
    # returns: the random stream is rewound to where verify=None would be at each step
    state_before_report = gen.bit_generator.state
    input_consistency = _consistency(pairs, input_assignments, lay.sync_sizes, gen)

    matching = info.pop("matching", None)
    build_output = info.pop("build_output", None)      # a closure: never left in the result
    if verify is not None:
        t = time.perf_counter()
        state = gen.bit_generator.state
        verified_maps = _verify_stage(graphs, pairs, assignments, verify, executor, gen,
                                      progress, info)
        timings["verify"] = time.perf_counter() - t
        # the share of pairs the first (simplest) model verifies decides: a richer model
        # verifies more pairs of non-rigid views too (points jittered by half their spacing:
        # 0.36-0.64 affine, 0.56-0.84 affine or homography; docs/methods/subgraphs.md)
        share = float(np.mean(info["verify"]["verified_first"]))
        info["verify"]["used"] = used = not verify[2] or share >= AUTO_VERIFY_MIN_SHARE
        if used:     # synchronize the verified maps (hard), as they are
            assignments, soft, refine, matching = verified_maps, None, False, None
        elif build_output is not None:
            # verify="auto", online: one plane transform explains too few pairs; the output
            # is built, and the input reported, in verify=None's order
            verify, gen.bit_generator.state = None, state_before_report
            build_output()
            matching = info.pop("matching")
            input_consistency = _consistency(pairs, input_assignments, lay.sync_sizes, gen)
        else:        # verify="auto", offline: as if it had not run
            verify, gen.bit_generator.state = None, state
    if sync is not None and matching is None:
        t = time.perf_counter()
        if verify is None:
            out = _synchronize(pairs, assignments, soft, lay, lay.n_universe, sync, gen)
            matching, rule = out.matching, out.info.get("n_universe_rule", "")
        else:
            matching, rule = _synchronize_verified(pairs, assignments, lay, sync, gen,
                                                   info["verify"]["verified"])
        info["n_universe_rule"] = rule
        timings["sync"] = timings.get("sync", 0.0) + time.perf_counter() - t
    if matching is not None and refine:
        t = time.perf_counter()
        matching = _refine(matching, pairs, assignments, aff, info)
        timings["refine"] = time.perf_counter() - t
    if matching is not None:
        matching = lay.strip_matching(matching)
        assignments = matching.pairwise_array(pairs)
        consistency = 1.0
        info["n_universe_rule"] = _universe_rule(lay, info.get("n_universe_rule", ""))
    else:
        assignments = lay.strip_dummies(pairs, assignments)
        consistency = _consistency(pairs, assignments, lay.sizes, gen)
    scores = aff.score_assignments(np.arange(len(pairs)), lay.widen(assignments))
    timings["total"] = time.perf_counter() - t_start
    return MultiMatchingResult(
        pairs=pairs, assignments=np.asarray(assignments, dtype=np.int64), matching=matching,
        scores=np.asarray(scores, dtype=float), total_score=float(np.sum(scores)),
        consistency=float(consistency), input_consistency=float(input_consistency),
        timings=timings, solver=solver, sync=sync, mode=mode, n_iter=int(n_iter),
        converged=not unconverged, n_graphs=N, info=info, sizes=lay.sizes)


# --------------------------------------------------------------------------- layout


@dataclass(frozen=True)
class _Layout:
    """How the graphs' sizes map onto the solvers' one shape (see :func:`match_collection`).

    ``kind``: ``"full"`` (equal sizes, full permutations), ``"universe"`` (pairwise stage padded
    to the largest graph, dummies stripped before the synchronization, partial permutations into
    ``n_universe`` slots) or ``"dummies"`` (the whole method on graphs padded to ``n_pad``,
    dummies dropped from the output).
    """

    sizes: np.ndarray
    n_pad: int
    kind: str
    n_universe: int | None

    @property
    def n_max(self) -> int:
        return int(self.sizes.max())

    @property
    def sync_sizes(self) -> np.ndarray:
        """Object sizes as the synchronization sees them."""
        if self.kind == "universe":
            return self.sizes
        return np.full(self.sizes.size, self.n_pad)

    @property
    def sync_universe(self) -> int | None:
        """Universe size handed to the synchronization (``None``: estimate)."""
        return self.n_universe if self.kind == "universe" else self.n_pad

    def strip(self, pairs, A):
        """Pairwise-stage maps ``(P, n_pad)`` without the dummies (universe kind only)."""
        if A is None or self.kind != "universe":
            return A
        return _strip_maps(pairs, A, self.sizes)

    def strip_dummies(self, pairs, A):
        """Output maps of an unsynchronized method on padded graphs, dummies dropped."""
        return _strip_maps(pairs, A, self.sizes) if self.kind == "dummies" else A

    def strip_matching(self, m: MultiMatching) -> MultiMatching:
        if self.kind != "dummies":
            return m
        return MultiMatching([lab[:k] for lab, k in zip(m.labels, self.sizes.tolist())],
                             m.n_universe)

    def widen(self, A) -> np.ndarray:
        """Maps ``(P, k)`` padded with -1 to the solvers' width ``n_pad`` (for scoring)."""
        A = np.asarray(A, dtype=np.int64)
        if A.shape[1] == self.n_pad:
            return A
        out = np.full((A.shape[0], self.n_pad), -1, dtype=np.int64)
        out[:, :A.shape[1]] = A
        return out


def _universe_rule(lay: _Layout, estimated: str) -> str:
    """How the output's universe size was set (``res.info["n_universe_rule"]``)."""
    if lay.kind == "dummies":
        return f"dummy-node baseline: every graph padded to {lay.n_pad} nodes"
    if lay.n_universe is not None:
        return "given (n_universe)"
    if lay.kind == "full":
        return "equal sizes: d = n"
    return estimated or "estimated by the synchronization"


def _real_blocks(X, pairs, sizes) -> np.ndarray:
    """Soft blocks ``(P, n_pad, n_pad)`` cut to the real nodes: ``(P, n_max, n_max)``, block
    ``p`` zero beyond ``n_i x n_j``."""
    n_max = int(sizes.max())
    out = np.array(X[:, :n_max, :n_max], dtype=float)
    idx = np.arange(n_max)
    out *= idx[None, :, None] < sizes[pairs[:, 0]][:, None, None]
    out *= idx[None, None, :] < sizes[pairs[:, 1]][:, None, None]
    return out


def _strip_maps(pairs, A, sizes) -> np.ndarray:
    """Maps between padded graphs -> maps between the real nodes ``(P, max n_i)``, -1 where a
    real node went to a dummy (and as padding beyond ``n_i``)."""
    A = np.asarray(A, dtype=np.int64)
    n_max = int(sizes.max())
    out = A[:, :n_max].copy()
    out[out >= sizes[pairs[:, 1]][:, None]] = -1
    out[np.arange(n_max)[None, :] >= sizes[pairs[:, 0]][:, None]] = -1
    return out


def _check_layout(graphs, n_universe, partial, solver, affinity) -> _Layout:
    sizes = np.array([g.n_nodes for g in graphs], dtype=np.int64)
    n_max = int(sizes.max())
    if not isinstance(partial, str) or partial not in PARTIAL:
        raise ValueError(f"`partial` must be one of {', '.join(map(repr, PARTIAL))}, got "
                         f"{partial!r}")
    if n_universe is not None:
        n_universe = check_int(n_universe, "n_universe", minimum=1)
        if n_universe < n_max:
            raise ValueError(f"`n_universe` must be >= the largest graph's size {n_max} (graph "
                             f"{int(np.argmax(sizes))}), got {n_universe}")
        if n_universe > int(sizes.sum()):
            raise ValueError(f"`n_universe` must be <= the total number of nodes "
                             f"{int(sizes.sum())}, got {n_universe}")
    equal = bool(np.all(sizes == n_max))
    if equal and n_universe in (None, n_max):
        return _Layout(sizes, n_max, "full", n_universe)
    if partial == "dummies":
        lay = _Layout(sizes, n_universe or n_max, "dummies", n_universe)
    else:
        lay = _Layout(sizes, n_max, "universe", n_universe)
    what = (f"graphs of different sizes {sizes.tolist()[:12]}" if not equal
            else f"n_universe={n_universe} > n={n_max}")
    if lay.kind == "universe" and solver in CAO_VARIANTS:
        raise ValueError(f"`partial` must be 'dummies' with solver={solver!r}: CAO composes "
                         f"full permutations; {what} need the dummy-node padding, got "
                         f"partial={partial!r}")
    if isinstance(affinity, np.ndarray) and affinity.dtype != object and not equal:
        raise ValueError(f"`affinity` as one (N, N, n*n, n*n) array holds graphs of one size n; "
                         f"{what} need a dict {{(i, j): K_ij}} of (n_i n_j, n_i n_j) blocks or "
                         "a callable (g_i, g_j) -> Affinity")
    return lay


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
        raise ValueError(f"`mode` must be 'offline' with solver={solver!r}, which runs "
                         f"offline only (mode='online' synchronizes inside the solvers "
                         f"{ONLINE_SOLVERS}), got mode='online'")
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
    if pairs is None:
        return all_pairs(N)
    arr = check_array(pairs, "pairs", dtype=None)
    if (arr.ndim == 2 and arr.shape[1:] == (2,) and arr.size and arr.dtype.kind in "iuf"
            and np.all(np.isfinite(arr)) and np.all(arr == np.floor(arr))
            and arr.min() >= 0 and arr.max() < N):      # else check_pairs says what is wrong
        same = np.flatnonzero(arr[:, 0] == arr[:, 1])
        if same.size:
            raise ValueError(f"`pairs[{same[0]}]` pairs graph {arr[same[0], 0]} with itself")
        check_index_pairs(arr, N, unique=True)   # a repeat named as given, e.g. (1, 0)
        arr = np.sort(arr, axis=1)
    # shape, integer indices in range, no repeated pair (and all of them for CAO)
    arr = check_pairs(arr, N, complete="CAO composes maps through every third graph"
                      if need_all else None)
    if need_connected:
        from scipy.sparse import coo_matrix
        from scipy.sparse.csgraph import connected_components

        A = coo_matrix((np.ones(len(arr)), (arr[:, 0], arr[:, 1])), shape=(N, N))
        n_comp, _ = connected_components(A, directed=False)
        if n_comp > 1:
            raise ValueError(f"`pairs` leaves the {N} graphs in {n_comp} disconnected groups; "
                             "synchronization needs a connected view graph (or use sync=None)")
    return arr


def _check_verify(verify, threshold, graphs, lay: "_Layout"):
    """``(model, threshold, auto)`` of the geometric verification, or None.

    ``verify="auto"`` resolves to :data:`AUTO_VERIFY_MODEL` (``("affine", "homography")``)
    when the graphs are partial views of a universe
    (``lay.kind == "universe"``: different sizes, or ``n_universe`` above their size) and every
    graph has 2-d points, and to None otherwise; ``auto`` is then True (see :func:`_run`).
    """
    from ..matching import VERIFY_MODELS

    auto = isinstance(verify, str) and verify == "auto"
    if auto:
        if lay.kind == "universe" and all(g.points is not None and g.points.shape[1] == 2
                                          for g in graphs):
            verify = AUTO_VERIFY_MODEL
        elif threshold is not None:
            why = ("the graphs are not partial views of one universe: equal sizes and no "
                   "larger `n_universe`, or partial='dummies'"
                   if lay.kind != "universe" else "not every graph has 2-d points")
            raise ValueError(f"`verify_threshold` sets the gate of the geometric verification, "
                             f"which verify='auto' runs none of here ({why}): pass "
                             f"verify='affine' (or 'similarity', 'homography') to force one, got "
                             f"verify_threshold={threshold!r}")
        else:
            return None
    if verify is None:
        if threshold is not None:
            raise ValueError(f"`verify_threshold` sets the gate of the geometric verification, "
                             f"which verify=None runs none of: pass verify='affine' (or "
                             f"'similarity', 'homography'), got verify_threshold={threshold!r}")
        return None
    models = check_choices(verify, "verify", tuple(VERIFY_MODELS),
                           what=" (each pair keeps the better supported), 'auto' or None")
    verify = models[0] if isinstance(verify, str) else models
    if threshold is not None:
        threshold = check_positive(threshold, "verify_threshold")
    if lay.kind == "dummies":
        raise ValueError(f"`verify` checks matches between the graphs' points, and the "
                         f"dummy-node baseline's padded nodes have none: use "
                         f"partial='universe' with verify={verify!r}, got partial='dummies'")
    for k, g in enumerate(graphs):
        if g.points is None or g.points.shape[1] != 2:
            what = "no points" if g.points is None else f"{g.points.shape[1]}-d points"
            raise ValueError(f"`verify={verify!r}` fits plane transforms between the graphs' "
                             f"2-d points; graph {k} has {what}")
    return verify, threshold, auto


# --------------------------------------------------------------------------- stages


def _verify_chunk(payload):
    """Worker (module level, picklable): verify a chunk of pairs' maps."""
    from ..matching import verify_assignment

    points, pairs, assignments, seeds, model, gate = payload
    out = np.full_like(assignments, -1)
    n_inliers = np.zeros(len(pairs), dtype=np.int64)
    verified = np.zeros(len(pairs), dtype=bool)
    models = np.empty(len(pairs), dtype=object)
    first = np.zeros(len(pairs), dtype=bool)
    for p, (i, j) in enumerate(pairs):
        ni = len(points[i])
        try:
            res = verify_assignment(points[i], points[j], assignments[p, :ni], model=model,
                                    rng=int(seeds[p]), **gate)
        except ValueError as exc:           # name the graphs, not verify_assignment's arguments
            raise ValueError(f"`verify={model!r}` cannot check the matches of graphs[{i}] and "
                             f"graphs[{j}] (points1 = graphs[{i}].points, points2 = "
                             f"graphs[{j}].points): {exc}") from None
        out[p, :ni] = res.assignment
        n_inliers[p], verified[p], models[p] = res.n_inliers, res.verified, res.model
        first[p] = next(iter(res.support.values())) > 0
    return out, n_inliers, verified, models.astype(str), first


def _verify_stage(graphs, pairs, assignments, verify, executor, gen, progress,
                  info) -> np.ndarray:
    """Every pair's map (between real nodes) through ``verify_assignment``.

    Each pair has its own seed, drawn here, so the result does not depend on ``executor``.
    """
    model, threshold, auto = verify
    gate = {} if threshold is None else {"threshold": threshold}
    A = np.asarray(assignments, dtype=np.int64)
    seeds = gen.integers(2**63, size=len(pairs))
    points = [g.points for g in graphs]
    chunks = split_chunks(len(pairs), executor)
    out = np.full_like(A, -1)
    n_inliers = np.zeros(len(pairs), dtype=np.int64)
    verified = np.zeros(len(pairs), dtype=bool)
    first = np.zeros(len(pairs), dtype=bool)
    names = (model,) if isinstance(model, str) else model
    pair_models = np.full(len(pairs), names[0], dtype=f"<U{max(map(len, names))}")
    # threshold None: verify_assignment's
    info["verify"] = {"model": model, "threshold": threshold, "n_inliers": n_inliers,
                      "verified": verified, "pair_models": pair_models,
                      "verified_first": first, "auto": auto}
    try:
        outs = map_chunks(_verify_chunk, [(points, pairs[idx], A[idx], seeds[idx], model, gate)
                                          for idx in chunks],
                          executor=executor, progress=progress, desc="verify pairs")
    except ValueError as exc:
        if not auto:
            raise
        # verify="auto" was not asked for by name: points that verify_assignment refuses
        # (e.g. coordinates beyond its range) mean no verification, not an error
        info["verify"]["refused"] = str(exc)
        return out
    for idx, (o, n_in, ok, kept, ok_first) in zip(chunks, outs):
        out[idx], n_inliers[idx], verified[idx], pair_models[idx] = o, n_in, ok, kept
        first[idx] = ok_first
    return out


def _pair_affinities(graphs, pairs, affinity, n) -> PairAffinities:
    if affinity is None or callable(affinity):
        return PairAffinities.from_graphs(graphs, pairs, affinity, n_pad=n)
    if isinstance(affinity, (Mapping, list, tuple, np.ndarray)):
        sizes = np.array([g.n_nodes for g in graphs])
        if (isinstance(affinity, np.ndarray) and affinity.dtype != object
                and affinity.ndim >= 2 and not np.all(sizes == n)):
            # graphs of one size padded with dummies (n_universe > n): the array's blocks,
            # as the (N, N) nested blocks that the padding takes (views, no copy)
            affinity = [list(row) for row in affinity]
        return PairAffinities.from_blocks(affinity, pairs, n, n_graphs=len(graphs),
                                          sizes=None if np.all(sizes == n) else sizes,
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
        pair_affs = [aff.pair(p) for p in range(len(aff))]
        # named as match_collection's argument here (the pairwise solvers call it `K`)
        check_affinity_scale([a.max_column_sum() for a in pair_affs], "affinity")
        results = [fn(a, **(options or {})) for a in pair_affs]
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
    """The online synchronization step: soft iterates ``(P, n, n)`` -> synchronized blocks.

    Universe layout: the real blocks ``X_p[:n_i, :n_j]`` (sub-doubly stochastic) are
    synchronized on the multi-simplex; the synchronized real block goes back with the slack of
    every real row and column spread over the dummies (:func:`_with_slack`).
    """

    def __init__(self, pairs, lay, sync, gen):
        self.pairs, self.lay, self.sync, self.gen = pairs, lay, sync, gen
        self.last = None                 # last sync result (warm start, universe size)
        self.first_rounding = None
        self.d = None                    # universe size fixed before the first point
        self.seconds = 0.0

    @property
    def n_universe(self):
        """The universe of the synchronization points (fixed by the first one)."""
        if self.last is None:
            return self.d if self.d is not None else self.lay.sync_universe
        return int(self.last.n_universe)

    def __call__(self, X):
        t = time.perf_counter()
        lay, pairs = self.lay, self.pairs
        if self.first_rounding is None:
            self.first_rounding = round_blocks(X)
        if self.sync == "birkhoff":
            d = None if self.last is not None else self.n_universe
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", ConvergenceWarning)
                res = synchronize_doubly_stochastic(
                    _by_pair(pairs, X, lay.sync_sizes), init=self.last, n_universe=d,
                    max_iter=SYNC_POINT_ITER, rng=self.gen)
            self.last = res
            Y = res.stacked_blocks(pairs)
        else:
            res = _synchronize(pairs, lay.strip(pairs, round_blocks(X)), None, lay,
                               self.n_universe, self.sync, self.gen)
            self.last = res.matching
            M = res.matching.pairwise_array(pairs)
            Y = np.zeros((len(M), lay.n_pad, lay.n_pad))
            p, u = np.nonzero(M >= 0)
            Y[p, u, M[p, u]] = 1.0
        if lay.kind == "universe":
            Y = _with_slack(Y, pairs, lay.sizes, lay.n_pad)
        self.seconds += time.perf_counter() - t
        return Y


def _with_slack(Y, pairs, sizes, n) -> np.ndarray:
    """Real blocks ``Y[p, :n_i, :n_j]`` (sub-doubly stochastic) completed to ``n x n`` blocks
    whose rows and columns sum to 1 where the dummies allow it: the slack ``1 - row sum`` of a
    real row is spread evenly over the dummy columns, a real column's over the dummy rows, and
    the dummy-dummy corner takes what is left (clipped at 0); the solvers' next step
    re-normalizes."""
    P = len(pairs)
    out = np.zeros((P, n, n))
    k = Y.shape[1]
    out[:, :k, :k] = Y[:, :n, :n]
    ni, nj = sizes[pairs[:, 0]], sizes[pairs[:, 1]]
    idx = np.arange(n)
    real_r = idx[None, :] < ni[:, None]                      # (P, n)
    real_c = idx[None, :] < nj[:, None]
    block = real_r[:, :, None] & real_c[:, None, :]
    out *= block
    row_slack = np.where(real_r, 1.0 - out.sum(2), 0.0).clip(0.0)
    col_slack = np.where(real_c, 1.0 - out.sum(1), 0.0).clip(0.0)
    kr, kc = (n - ni).astype(float), (n - nj).astype(float)   # dummy rows of i, columns of j
    with np.errstate(divide="ignore", invalid="ignore"):
        to_dcols = np.where(kc[:, None] > 0, row_slack / kc[:, None], 0.0)
        to_drows = np.where(kr[:, None] > 0, col_slack / kr[:, None], 0.0)
        corner = np.where((kr > 0) & (kc > 0),
                          (1.0 - col_slack.sum(1) / np.maximum(kr, 1)) / np.maximum(kc, 1), 0.0)
    dummy_r, dummy_c = ~real_r, ~real_c
    out += (real_r[:, :, None] & dummy_c[:, None, :]) * to_dcols[:, :, None]
    out += (dummy_r[:, :, None] & real_c[:, None, :]) * to_drows[:, None, :]
    out += (dummy_r[:, :, None] & dummy_c[:, None, :]) * corner.clip(0.0)[:, None, None]
    return out


def _online_stage(aff, N, lay, solver, sync, options, sync_every, damping, gen, progress,
                  timings, info, *, build_output: bool = True):
    """The lock-step solvers with synchronization points. ``build_output``: also build and
    score the consistent output candidates; ``False`` (a verification may replace them): the
    builder is left in ``info["build_output"]``, to call if it does not (the caller pops it:
    a closure, not picklable)."""
    point = _SyncPoint(aff.pairs, lay, sync, gen)
    rule, candidates = "", {}
    if lay.kind == "universe" and lay.n_universe is None:
        # The universe size is fixed once, before the first synchronization point, from the
        # eigengap of the *converged* unsynchronized pairwise solutions (measured, N = 8,
        # d = 20, deformation 0.1: right on 9 of 10 collections, against 6 of 10 from the
        # roundings at the first point), of their soft matrices (``_synchronize``); that
        # synchronization is also an output candidate.
        t = time.perf_counter()
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", ConvergenceWarning)
            pre = run_lockstep(aff, solver=solver, sync=None, options=options, progress=False)
        timings["universe"] = time.perf_counter() - t
        est = _synchronize(aff.pairs, lay.strip(aff.pairs, pre.assignments), pre.soft, lay,
                           None, "spectral", gen)
        point.d = int(est.matching.n_universe)
        candidates["pairwise_sync"] = est.matching
        rule = ("estimated once from the unsynchronized pairwise solutions: "
                + est.info.get("n_universe_rule", ""))
        timings["universe"] = time.perf_counter() - t
    t = time.perf_counter()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ConvergenceWarning)
        out = run_lockstep(aff, solver=solver, sync=point, sync_every=sync_every,
                           damping=damping, options=options, progress=progress)
    timings["pairwise"] = time.perf_counter() - t - point.seconds
    first_rounding, seconds_at_points = point.first_rounding, point.seconds
    final = out.assignments          # the solvers' own rounding (as transync.matching's)
    first = first_rounding if first_rounding is not None else final
    timings["sync"] = seconds_at_points
    info.update({"n_sync": out.n_sync, "input_assignments": first})

    def build():
        """Score the consistent output candidates; the best goes to ``info["matching"]``."""
        t = time.perf_counter()
        method = "spectral" if sync == "birkhoff" else sync
        perm = _synchronize(aff.pairs, lay.strip(aff.pairs, final), None, lay,
                            point.n_universe, method, gen)
        candidates["permutation_sync"] = perm.matching
        if sync == "birkhoff":
            point(doubly_stochastic_iterates(out.soft))   # one last warm-started sync point
            candidates["map_atom"] = point.last.matching
        elif isinstance(point.last, MultiMatching):
            candidates["last_sync"] = point.last
        idx = np.arange(len(aff.pairs))
        scores = {k: float(np.sum(aff.score_assignments(idx, lay.widen(
            m.pairwise_array(aff.pairs))))) for k, m in candidates.items()}
        best = max(scores, key=scores.get)
        timings["sync"] += time.perf_counter() - t
        info.update({"output": best, "candidate_scores": scores, "matching": candidates[best],
                     "n_universe_rule": rule or perm.info.get("n_universe_rule", "")})

    if build_output:
        build()
    else:
        info["build_output"] = build
    return final, out.soft, out.n_iter, int(np.sum(~out.converged))


def _refine(matching, pairs, proposals, aff, info) -> MultiMatching:
    """Consistent coordinate ascent from the synchronized configuration (module _refine)."""
    if np.any(matching.sizes != matching.sizes[0]):
        return matching                       # partial maps: nothing to re-anchor
    L = np.stack(matching.labels)
    if np.any(L < 0) or np.any(np.sort(L, axis=1) != np.arange(L.shape[1])):
        return matching                       # not a full configuration: nothing to re-anchor
    symmetric = not aff.asymmetric().any()

    def gradient(p_idx, X):                   # (K + K^T) vec(X) of pairs p_idx
        KX = aff._product(X, p_idx)
        return 2.0 * KX if symmetric else KX + aff._product(X, p_idx, True)

    L, history, moves = refine_consistent(L, pairs, np.asarray(proposals, dtype=np.int64),
                                          aff.score_assignments, gradient=gradient)
    info["refine"] = {"score_history": history, "sweeps": len(history) - 1, "moves": moves}
    return MultiMatching(list(L), matching.n_universe)


def _by_pair(pairs, values, sizes=None) -> dict:
    """``{(i, j): values[p]}`` for ``pairs[p] = (i, j)``: the synchronizers' pairwise input
    (blocks cut to ``sizes[i] x sizes[j]`` when ``sizes`` is given)."""
    if sizes is None:
        return {(int(i), int(j)): values[p] for p, (i, j) in enumerate(pairs.tolist())}
    return {(int(i), int(j)): values[p][:sizes[i], :sizes[j]]
            for p, (i, j) in enumerate(pairs.tolist())}


def _synchronize_verified(pairs, assignments, lay, sync, gen, verified):
    """The verified maps synchronized: ``(matching, rule)``.

    With the universe size to estimate, a pair that failed its verification is *unobserved*
    (no transform explains its matches: no evidence either way), not an observation that its
    graphs share no node, which would inflate the estimate (5 affine views of 24 points, 6 of
    10 pairs verified: 48 slots and F1 0.57 with the failed pairs as empty maps, 24 and 1.0
    without them); verified pairs that leave the graphs in several groups give each group its
    own slots. With ``n_universe`` given, failed pairs enter as empty maps, so that every graph
    stays in the one universe asked for. Either way a node whose slot no verified match
    supports is left unplaced; no verified pair at all: every node unplaced.
    """
    if not np.any(verified):
        d = lay.n_universe or lay.n_max
        return (MultiMatching([np.full(k, -1, dtype=np.int64) for k in lay.sizes.tolist()], d),
                "no pair verified: every node unplaced")
    use = verified if lay.n_universe is None else np.ones_like(verified)
    out = _synchronize(pairs[use], np.asarray(assignments)[use], None, lay, lay.n_universe,
                       sync, gen, min_score=VERIFY_MIN_SCORE)
    rule = out.info.get("n_universe_rule", "")
    if lay.n_universe is None:
        rule = f"estimated from the verified maps ({int(use.sum())} pairs): {rule}"
    return out.matching, rule


def _synchronize(pairs, assignments, soft, lay, n_universe, sync, gen, min_score=None):
    """One synchronization of the pairwise stage's output (``assignments`` between the graphs
    the synchronization sees) into universe labels; the synchronizer's result (``.matching``,
    ``.info``). ``min_score``: of :func:`~transync.synchronize_permutations` (hard maps)."""
    sizes = lay.sync_sizes
    if lay.kind != "universe":
        n_universe = lay.n_pad
    A = np.asarray(assignments)
    maps = {(int(i), int(j)): A[p, :sizes[i]] for p, (i, j) in enumerate(pairs.tolist())}
    rule = None
    estimate = lay.kind == "universe" and n_universe is None
    # On an incomplete view graph the eigengap rule overestimates the universe, on soft blocks
    # and rounded maps alike; synchronize_permutations then applies its rule for that case
    # (the slots its orthogonal synchronization uses), which decides for every method here.
    incomplete = len(pairs) < len(sizes) * (len(sizes) - 1) // 2
    if sync == "birkhoff" and soft is not None:
        if estimate and incomplete:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", ConvergenceWarning)
                est = synchronize_permutations(maps, method="spectral", sizes=sizes, rng=gen)
            n_universe, rule = int(est.n_universe), est.info.get("n_universe_rule", "")
        soft = doubly_stochastic_iterates(soft)       # solver iterates are DS to ~1e-3 only
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", ConvergenceWarning)
            out = synchronize_doubly_stochastic(_by_pair(pairs, soft, sizes),
                                                n_universe=n_universe, rng=gen)
        if rule is not None:
            out.info["n_universe_rule"] = rule
        return out
    method = "spectral" if sync in ("birkhoff", "spectral") else "orthogonal"
    if (estimate and not incomplete and soft is not None
            and int(sizes.sum()) <= SOFT_UNIVERSE_MAX):
        # The soft solutions keep the solver's uncertainty, which its rounded maps lose: a
        # universe node kept by few graphs whose hard matches went to other nodes keeps part
        # of its eigenvalue (estimate_universe; N = 8, d = 20, RRWM, 400 collections of
        # benchmarks/universe_estimate.py: right on 93.2 % against 92.0 % from the maps, 94.0 %
        # with its split-gap step; on 880 collections over four settings 83.8 % against
        # 81.4 %, before that step).
        est = estimate_universe(_by_pair(pairs, doubly_stochastic_iterates(soft), sizes),
                                sizes=sizes)
        n_universe, rule = est.n_universe, f"soft {est.rule} (the pairwise solver's soft solutions)"
    # In a universe larger than the data needs, the spectral rounding split slots (exact
    # partial input, d = 20 for a true 12: accuracy 0.64, before synchronize_permutations left
    # out the null-space eigenvectors: now 1.0); on noisy maps the projected-power sweeps
    # still merge slots that the rounding splits, as the orthogonal method always does.
    refine = UNIVERSE_REFINE if lay.kind == "universe" and method == "spectral" else None
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ConvergenceWarning)
        out = synchronize_permutations(maps, method=method, n_universe=n_universe,
                                       sizes=sizes, refine=refine, min_score=min_score,
                                       rng=gen)
    if rule is not None:
        out.info["n_universe_rule"] = rule
    return out


def _consistency(pairs, assignments, sizes, gen) -> float:
    if assignments is None or len(pairs) < 3:
        return 1.0
    rep = cycle_inconsistency_arrays(pairs, np.asarray(assignments), sizes, rng=gen)
    return 1.0 - float(rep["cycle_error"]) if rep["n_triangles"] else 1.0
