"""Multi-subgraph matching through a universe (thesis ch. 7: Figs. 7.2-7.6, Table 7.2).

Graphs of different sizes drawn from a universe of ``d`` nodes
(:func:`transync.datasets.make_subgraph_collection`: every graph keeps each universe node with
its own probability ``p ~ U(p_low, p_high)``, plus outliers, deformation, edge density and
topological noise; node orders shuffled) are matched with one method through
:func:`transync.match_collection`, on Yan et al.'s edge affinity ``exp(-(e - e')^2 / 0.05)``.
All methods of a trial see the same collection. Methods (:data:`METHODS`):

* ``S-RRWM``, ``S-GA`` - the thesis's method: lock-step solvers with slack whose iterates are
  synchronized on the multi-simplex during the optimization, the universe size estimated
  (``partial="universe"``, ``mode="online"``, ``n_universe=None``);
* ``RRWM+Birkhoff``, ``RRWM+spectral`` - pairwise RRWM with slack, synchronized once afterwards
  (``mode="offline"``);
* ``RRWM`` - every pair matched on its own (``sync=None``): not consistent;
* ``S-RRWM dummies``, ``S-GA dummies`` - the dummy-node baseline (thesis Fig. 7.3): every graph
  padded with isolated dummies to the largest size, the full-permutation method run, matches
  involving dummies dropped (``partial="dummies"``);
* ``S-RRWM known d`` - ``S-RRWM`` told the universe size (``n_universe = max(d, largest graph)``);
* ``S-RRWM verified``, ``S-GA verified``, ``RRWM+spectral verified`` - on the ``cmu`` sweep only
  (:data:`VERIFIED`: graphs with points): the same methods with the geometric verification of
  the pairwise maps before the synchronization (``verify="affine"``);
* ``S-RRWM verified A/H``, ``RRWM+spectral verified A/H`` - the same with every pair keeping
  the better supported of an affine map and a homography (``verify=("affine",
  "homography")``, what ``verify="auto"`` runs: ``S-RRWM verified A/H`` is the default call).

Sweeps, one variable at a time around N = 8 graphs, d = 20, ``p_keep`` in [0.6, 1], no
outliers, deformation 0.05, complete graphs (grid: ``docs/experiments/subgraph/README.md``):
``deformation``, ``flip`` (topological noise) and ``range`` (the low end ``p_low`` of the keep
probability: range of graph sizes) for Figs. 7.2, 7.3, 7.5 and 7.6; ``equal_deformation`` and
``equal_flip`` with ``p_keep = 1`` and 2 outliers per graph (equal sizes, Fig. 7.4); and
``cmu``: CMU House partial, N = 20 frames spread over the sequence, each keeping a random 20-25
of its 30 landmarks (two thirds to five sixths of the landmarks of other sequences), node orders
shuffled, Delaunay graphs, the length + angle affinity of the ``cmu`` experiment. The ``cmu``
sweep runs when the data folder is found (``build(data=...)``, ``--data``; default
``TRANSYNC_DATA``'s ``cmu-house``) and is left out otherwise.

Metrics per trial (:func:`subgraph_metrics`): ``precision``, ``recall``, ``f1``, ``accuracy``
on real-to-real correspondences (:func:`transync.metrics.multimatching_precision_recall`),
``n_universe`` (the size the method used or estimated; NaN for ``RRWM``), ``universe_ok``
(whether it equals the true universe size: the universe nodes present in at least one graph),
``universe_error`` (estimate - truth), the capacity and transitivity ``*_cvr``, ``*_cvvr``,
``*_acvv`` of the discrete output's pairwise maps
(:func:`transync.metrics.constraint_violations`) and, when the result exposes the pairwise
stage's soft matrices (``res.info["soft"]``), the same of the soft output (``soft_*``);
``seconds`` (``match_collection`` wall time), ``size_min``, ``size_max``.

Besides the standard plot, a run writes ``fig_7_2.png``, ``fig_7_3_dummies.png``,
``fig_7_4_equal_sizes.png``, ``fig_7_5_violations.png``, ``fig_7_6_violations.png``,
``table_7_2.md`` (constraint violations), ``table_universe.md`` (universe estimation and the F1
lost when it is wrong), ``table_cmu.md`` (the CMU House partial point) and ``table_targets.md``
(issue #11's targets checked on the stored trials).
"""

from __future__ import annotations

import dataclasses
import functools
import math
import time
import warnings
from pathlib import Path

import numpy as np

from ..datasets import LANDMARK_AFFINITY, data_home, make_subgraph_collection
from ..exceptions import ConvergenceWarning
from ..matching import gaussian_edge_affinity
from ..metrics import constraint_violations, multimatching_precision_recall
from ..multigraph import match_collection
from ._runner import Experiment, Sweep, mean_se, summarize, value_label
from .cmu import _load, draw_frames, load_sequence, sequence_fingerprint

#: method name -> keyword arguments of :func:`transync.match_collection` (``partial`` defaults
#: to ``"universe"`` and ``n_universe`` to ``None``: estimated); ``n_universe="d"`` is replaced
#: by the true universe size (at least the largest graph) in :func:`run_method`. ``verify`` is
#: explicit: ``match_collection``'s default, ``"auto"``, verifies graphs of different sizes with
#: points, so on the ``cmu`` sweep the ``verified A/H`` lines are what the defaults do (the
#: ``verified`` lines: the affine model alone, the default before 2026-11-27's evening)
METHODS = {
    "S-RRWM": {"solver": "rrwm", "sync": "birkhoff", "mode": "online", "verify": None},
    "S-GA": {"solver": "ga", "sync": "birkhoff", "mode": "online", "verify": None},
    "RRWM+Birkhoff": {"solver": "rrwm", "sync": "birkhoff", "mode": "offline", "verify": None},
    "RRWM+spectral": {"solver": "rrwm", "sync": "spectral", "mode": "offline", "verify": None},
    "RRWM": {"solver": "rrwm", "sync": None, "verify": None},
    "S-RRWM dummies": {"solver": "rrwm", "sync": "birkhoff", "mode": "online",
                       "partial": "dummies", "verify": None},
    "S-GA dummies": {"solver": "ga", "sync": "birkhoff", "mode": "online", "partial": "dummies",
                     "verify": None},
    "S-RRWM known d": {"solver": "rrwm", "sync": "birkhoff", "mode": "online",
                       "n_universe": "d", "verify": None},
    "S-RRWM verified": {"solver": "rrwm", "sync": "birkhoff", "mode": "online",
                        "verify": "affine"},
    "S-GA verified": {"solver": "ga", "sync": "birkhoff", "mode": "online", "verify": "affine"},
    "RRWM+spectral verified": {"solver": "rrwm", "sync": "spectral", "mode": "offline",
                               "verify": "affine"},
    "S-RRWM verified A/H": {"solver": "rrwm", "sync": "birkhoff", "mode": "online",
                            "verify": ("affine", "homography")},
    "RRWM+spectral verified A/H": {"solver": "rrwm", "sync": "spectral", "mode": "offline",
                                   "verify": ("affine", "homography")},
}
#: the line that is ``match_collection(graphs, affinity=...)`` with every other argument left at
#: its default on the ``cmu`` sweep's graphs (different sizes, 2-d points: ``verify="auto"``
#: verifies them with an affine model or a homography, whichever each pair supports better)
DEFAULT_METHOD = "S-RRWM verified A/H"
#: the methods that need points (geometric verification): the CMU sweep's extra lines
VERIFIED = tuple(m for m, kw in METHODS.items() if kw.get("verify"))
#: the methods of the synthetic sweeps (graphs without points)
GRAPH_METHODS = tuple(m for m in METHODS if m not in VERIFIED)
#: universe method -> its dummy-node baseline (the pairs compared by the targets table)
DUMMY_PAIRS = {"S-RRWM": "S-RRWM dummies", "S-GA": "S-GA dummies"}
#: the methods whose output is synchronized (cycle-consistent by construction)
SYNCHRONIZED = tuple(m for m, kw in METHODS.items() if kw.get("sync") is not None)
#: Yan et al.'s kernel width on U(0, 1) edge weights
SIGMA2 = 0.05
#: metrics of the standard plot and summary (``seconds`` is added by the runner)
METRICS = ("f1", "precision", "recall", "universe_ok", "transitivity_cvr")
#: the constraint-violation measures, per family
VIOLATIONS = tuple(f"{fam}_{m}" for fam in ("capacity", "transitivity")
                   for m in ("cvr", "cvvr", "acvv"))
#: synthetic sweeps with graphs of different sizes (the universe-estimation target's trials)
PARTIAL_SWEEPS = ("deformation", "flip", "range")

_UNIVERSE_LINES = ("S-RRWM", "S-GA", "RRWM+Birkhoff", "RRWM+spectral", "RRWM", "S-RRWM known d")
#: Fig. 7.5 / 7.6 lines: synchronized RRWM and GA against unsynchronized RRWM (the offline lines'
#: soft output is the same pairwise RRWM stage as RRWM's)
_VIOLATION_LINES = ("S-RRWM", "S-GA", "RRWM")
#: thesis figure -> (file name, methods, sweeps, metrics); for Figs. 7.5 and 7.6 :func:`finish`
#: adds the soft output's measures when stored and drops the discrete capacity ones (discrete
#: maps are injective: capacity holds trivially)
FIGURES = {
    "7.2": ("fig_7_2.png", _UNIVERSE_LINES, PARTIAL_SWEEPS, ("f1", "precision", "recall")),
    "7.3": ("fig_7_3_dummies.png", ("S-RRWM", "S-GA", "S-RRWM dummies", "S-GA dummies"),
            PARTIAL_SWEEPS, ("f1", "precision", "recall")),
    "7.4": ("fig_7_4_equal_sizes.png", GRAPH_METHODS, ("equal_deformation", "equal_flip"),
            ("f1", "precision", "recall")),
    "7.5": ("fig_7_5_violations.png", _VIOLATION_LINES, ("deformation", "range"),
            ("accuracy", "capacity_cvr", "transitivity_cvr")),
    "7.6": ("fig_7_6_violations.png", _VIOLATION_LINES, ("deformation", "range"),
            ("capacity_cvvr", "capacity_acvv", "transitivity_cvvr", "transitivity_acvv")),
}


def run_method(method: str, graphs, affinity, rng: np.random.Generator, *,
               n_universe: int | None = None, pairs=None):
    """Match ``graphs`` with one of :data:`METHODS`; returns ``(result, seconds)``.

    ``n_universe`` is the true universe size, used only by the methods told it
    (``"S-RRWM known d"``; raised to the largest graph when smaller, e.g. with outliers).
    ``pairs``: a view graph (default: every pair), as ``match_collection`` takes it.
    """
    if method not in METHODS:
        raise ValueError(f"`method` must be one of {', '.join(METHODS)}, got {method!r}")
    kwargs = dict(METHODS[method])
    if kwargs.get("n_universe") == "d":
        if n_universe is None:
            raise ValueError(f"method {method!r} is told the universe size: pass `n_universe`")
        kwargs["n_universe"] = max(int(n_universe), max(g.n_nodes for g in graphs))
    seed = int(rng.integers(2**31))
    t0 = time.perf_counter()
    with warnings.catch_warnings():     # pairs stopped at their budget: `res.converged`
        warnings.simplefilter("ignore", ConvergenceWarning)
        res = match_collection(graphs, affinity=affinity, rng=seed, progress=False,
                               pairs=pairs, **kwargs)
    return res, time.perf_counter() - t0


def _pairwise_maps(res) -> dict:
    """``{(i, j): (n_i,) assignment}`` over the result's pairs (padding stripped)."""
    return {(i, j): np.asarray(res.pairwise(i, j), dtype=np.int64)
            for i, j in np.asarray(res.pairs, dtype=np.int64).tolist()}


def _soft_blocks(res, sizes: np.ndarray) -> dict | None:
    """The pairwise stage's soft matrices ``{(i, j): (n_i, n_j)}`` when the result has them."""
    soft = (getattr(res, "info", None) or {}).get("soft")
    if soft is None:
        return None
    soft = np.asarray(soft, dtype=float)
    pairs = np.asarray(res.pairs, dtype=np.int64)
    if soft.ndim != 3 or soft.shape[0] != len(pairs):
        return None
    return {(i, j): soft[p, : sizes[i], : sizes[j]] for p, (i, j) in enumerate(pairs.tolist())}


def subgraph_metrics(res, truth, seconds: float, *, rng=None) -> dict:
    """Precision / recall / F1, universe size and constraint violations of one result.

    Parameters
    ----------
    res : MultiMatchingResult
        The output of :func:`transync.match_collection`.
    truth : MultiMatching
        The ground truth (``problem.ground_truth``; ``-1`` = outlier).
    seconds : float
        Wall time of the method.
    rng : None, int or Generator
        Randomness of the sampled soft transitivity evaluation (large collections only).

    Returns
    -------
    dict
        ``precision``, ``recall``, ``f1``, ``accuracy``, ``n_universe`` (NaN when nothing was
        synchronized), ``n_universe_true``, ``universe_ok`` (1.0 / 0.0, NaN when nothing was
        synchronized), ``universe_error``, the discrete output's ``capacity_*`` and
        ``transitivity_*`` ``cvr`` / ``cvvr`` / ``acvv``, ``soft_*`` the same of the soft
        output when the result stores it, ``seconds``, ``size_min``, ``size_max``.

    Examples
    --------
    >>> import functools, numpy as np
    >>> from transync.datasets import make_subgraph_collection
    >>> from transync.matching import gaussian_edge_affinity
    >>> p = make_subgraph_collection(n_graphs=3, n_universe=5, p_keep=1.0, rng=0)
    >>> aff = functools.partial(gaussian_edge_affinity, sigma2=SIGMA2)
    >>> res, sec = run_method("S-RRWM", p.graphs, aff, np.random.default_rng(0))
    >>> m = subgraph_metrics(res, p.ground_truth, sec)
    >>> m["f1"], m["universe_ok"], m["transitivity_cvr"]
    (1.0, 1.0, 0.0)
    """
    sizes = np.asarray(truth.sizes, dtype=np.int64)
    maps = _pairwise_maps(res)
    out = dict(multimatching_precision_recall(maps, truth))
    labels = np.concatenate([np.asarray(lab, dtype=np.int64) for lab in truth.labels])
    d_true = int(np.unique(labels[labels >= 0]).size)
    est = getattr(res, "n_universe", None)
    if est is None and getattr(res, "matching", None) is not None:
        est = res.matching.n_universe
    # with outliers every node still takes a slot: the inlier universe is no target to hit
    judged = est is not None and not np.any(labels < 0)
    out.update(n_universe=math.nan if est is None else float(est),
               n_universe_true=float(d_true),
               universe_ok=float(int(est) == d_true) if judged else math.nan,
               universe_error=float(int(est) - d_true) if judged else math.nan)
    viol = constraint_violations(maps, sizes=sizes)
    out.update({k: float(v) for k, v in viol.as_dict().items() if k in VIOLATIONS})
    soft = _soft_blocks(res, sizes)
    if soft is not None:
        sv = constraint_violations(soft, sizes=sizes, max_triples=200_000, rng=rng)
        out.update({f"soft_{k}": float(v) for k, v in sv.as_dict().items() if k in VIOLATIONS})
    out.update(seconds=float(seconds), size_min=float(sizes.min()),
               size_max=float(sizes.max()))
    return out


# ----------------------------------------------------------------------------------------------
# trials
# ----------------------------------------------------------------------------------------------

def cmu_keep_range(n_landmarks: int) -> tuple[int, int]:
    """Landmarks kept per frame in the partial protocol: two thirds to five sixths of them.

    >>> cmu_keep_range(30)
    (20, 25)
    >>> cmu_keep_range(10)
    (7, 8)
    """
    lo = max(1, math.ceil(2 * n_landmarks / 3))
    return lo, max(lo, (5 * n_landmarks) // 6)


def _synthetic_problem(config: dict, rng: np.random.Generator):
    low, high = float(config["p_low"]), float(config["p_high"])
    return make_subgraph_collection(
        n_graphs=config["n_graphs"], n_universe=config["n_universe"],
        p_keep=low if low == high else (low, high), n_outliers=config["n_outliers"],
        deformation=config["deformation"], density=config["density"], flip=config["flip"],
        shuffle=True, rng=rng)


def _cmu_problem(config: dict, rng: np.random.Generator, data: str):
    n = int(config["n_frames"])
    gap = max(1, (_load(data).n_frames - 1) // max(n - 1, 1))   # spread over the sequence
    seq, frames = draw_frames(data, config, n, gap, rng)
    keep = (int(config["keep_low"]), int(config["keep_high"]))
    return seq.graphs(frames, shuffle=True, keep=keep, rng=rng)


def trial(config: dict, rng: np.random.Generator, *, data: str | None = None) -> dict:
    """One generated collection (or one draw of CMU frames), one method of :data:`METHODS`.

    Synthetic configurations hold the generator's parameters (``n_graphs``, ``n_universe``,
    ``p_low``, ``p_high``, ``n_outliers``, ``deformation``, ``density``, ``flip``, ``sigma2``);
    CMU configurations (``"sequence"`` in the configuration) hold ``n_frames``, ``keep_low``,
    ``keep_high`` and the sequence's fingerprint, and need ``data`` (bound by :func:`build`).
    """
    if "sequence" in config:
        if data is None:
            raise ValueError("the cmu sweep needs the sequence's folder (`data`)")
        problem = _cmu_problem(config, rng, data)
        affinity = functools.partial(gaussian_edge_affinity, **LANDMARK_AFFINITY)
    else:
        problem = _synthetic_problem(config, rng)
        affinity = functools.partial(gaussian_edge_affinity,
                                     sigma2=config.get("sigma2", SIGMA2))
    truth = problem.ground_truth
    res, seconds = run_method(config["method"], problem.graphs, affinity, rng,
                              n_universe=truth.n_universe)
    return subgraph_metrics(res, truth, seconds, rng=rng)


# ----------------------------------------------------------------------------------------------
# the experiment
# ----------------------------------------------------------------------------------------------

def _find_sequence(data):
    """The CMU sequence of ``data`` (an error when given and unreadable), or of the default
    folder when it exists (``None`` when it does not)."""
    if data is not None:
        return load_sequence(data)
    try:
        folder = data_home(required=False, subfolder="cmu-house")
    except (FileNotFoundError, NotADirectoryError):
        return None
    if folder is None or not (Path(folder) / "label").is_dir():
        return None
    return load_sequence(folder)


def build(*, quick: bool = False, data=None) -> Experiment:
    """The sweeps of thesis ch. 7 (grid: ``docs/experiments/subgraph/README.md``).

    ``quick``: two values per sweep, N = 4 graphs over a universe of 8, 1 trial, 4 CMU frames
    (seconds); full: 20 trials per point. ``data``: a folder in the CMU layout for the ``cmu``
    sweep (default ``TRANSYNC_DATA``'s ``cmu-house``; the sweep is left out when that is
    missing, an error when ``data`` is given and unreadable).
    """
    base = dict(n_graphs=8, n_universe=20, p_low=0.6, p_high=1.0, n_outliers=0,
                deformation=0.05, density=1.0, flip=0.0, sigma2=SIGMA2)
    equal = dict(p_low=1.0, n_outliers=2)
    methods = GRAPH_METHODS
    if quick:
        base.update(n_graphs=4, n_universe=8)
        equal.update(n_outliers=1)
        deform, flip, p_low = [0.0, 0.2], [0.0, 0.2], [0.5, 1.0]
        n_frames, trials = 4, 1
    else:
        deform = [round(0.05 * k, 2) for k in range(6)]
        flip = [round(0.05 * k, 2) for k in range(7)]
        p_low = [round(0.3 + 0.1 * k, 1) for k in range(8)]
        n_frames, trials = 20, 20
    eq_base = {**base, **equal}
    sweeps = [
        Sweep(name="deformation", variable="deformation", values=deform, methods=methods,
              base=base, metrics=METRICS, xlabel="deformation noise σ"),
        Sweep(name="flip", variable="flip", values=flip, methods=methods, base=base,
              metrics=METRICS, xlabel="topological noise (edge flip probability)"),
        Sweep(name="range", variable="p_low", values=p_low, methods=methods, base=base,
              metrics=METRICS, xlabel="keep probability p ~ U(p_low, 1) (graph sizes)"),
        Sweep(name="equal_deformation", variable="deformation", values=deform,
              methods=methods, base=eq_base, metrics=METRICS,
              xlabel=f"deformation σ (equal sizes, {equal['n_outliers']} outliers)"),
        Sweep(name="equal_flip", variable="flip", values=flip, methods=methods, base=eq_base,
              metrics=METRICS,
              xlabel=f"edge flip probability (equal sizes, {equal['n_outliers']} outliers)"),
    ]
    seq = _find_sequence(data)
    path = None
    if seq is not None:
        path = str(Path(seq.source).resolve())
        n_frames = min(n_frames, seq.n_frames)
        if n_frames < 2:
            raise ValueError(f"the sequence in {path} has {seq.n_frames} frame(s); the cmu "
                             "sweep needs at least 2")
        lo, hi = cmu_keep_range(seq.n_landmarks)
        cmu_base = dict(sequence=seq.name, fingerprint=sequence_fingerprint(seq),
                        keep_low=lo, keep_high=hi)
        sweeps.append(Sweep(name="cmu", variable="n_frames", values=[n_frames],
                            methods=methods + VERIFIED, base=cmu_base, metrics=METRICS,
                            xlabel=f"frames of {seq.name!r}, {lo}-{hi} of "
                                   f"{seq.n_landmarks} landmarks each"))
    where = (f"; CMU partial: {seq.name} ({seq.n_frames} frames)" if seq is not None
             else "; CMU partial left out (no data folder)")
    return Experiment(name="subgraph", sweeps=sweeps, trial=functools.partial(trial, data=path),
                      trials=trials,
                      description="graphs of different sizes through a universe: "
                                  "universe vs dummy nodes, constraint violations" + where,
                      finish=functools.partial(finish, experiment_sweeps=tuple(sweeps)))


# ----------------------------------------------------------------------------------------------
# figures and tables
# ----------------------------------------------------------------------------------------------

def _has(records, metric: str) -> bool:
    return any(metric in r["metrics"] for r in records if not r["error"])


def finish(records, summary, out_dir, *, experiment_sweeps) -> list[Path]:
    """Figures 7.2-7.6 and the tables of :mod:`transync.experiments.subgraph` from the trials.

    Figures 7.5 and 7.6 show the discrete output's transitivity violations and, when the trials
    stored them, the soft output's capacity and transitivity violations (``soft_*``).
    """
    from ._plot import plot_experiment

    out = Path(out_dir)
    ok = [r for r in records if not r["error"]]
    ran = {r["sweep"] for r in ok}
    by_name = {sw.name: sw for sw in experiment_sweeps if sw.name in ran}
    soft = _has(ok, "soft_transitivity_cvr")
    paths = []
    for fig, (fname, methods, sweep_names, metrics) in FIGURES.items():
        note = ""
        if fig in ("7.5", "7.6"):     # discrete maps are injective: capacity holds trivially
            metrics = [m for m in metrics if not m.startswith("capacity_")] \
                + [f"soft_{m}" for m in metrics if soft and m != "accuracy"]
            # a measure that is exactly 0 in every trial (soft capacity of sub-doubly-
            # stochastic blocks) gets no panel, only a mention in the title
            zero = [m for m in metrics if m != "accuracy" and all(
                r["metrics"].get(m, 0.0) == 0.0 for r in ok if r["sweep"] in sweep_names)]
            metrics = tuple(m for m in metrics if m not in zero)
            if zero:
                note = "; 0 in every trial: " + ", ".join(m.replace("_", " ") for m in zero)
        sweeps = []
        for name in sweep_names:
            sw = by_name.get(name)
            if sw is None:
                continue
            kept = tuple(m for m in methods if m in sw.methods
                         and any(r["sweep"] == name and r["config"].get("method") == m
                                 for r in ok))
            if kept:
                sweeps.append(dataclasses.replace(sw, methods=kept, metrics=metrics))
        if not sweeps:
            continue
        sub = Experiment(name=f"Fig. {fig}", sweeps=sweeps, trial=trial,
                         description=", ".join(methods) + " (mean ± s.e.)" + note)
        paths.append(plot_experiment(sub, summarize(sub, records), out / fname))
    for writer in (_table_violations, _table_universe, _table_cmu, _table_targets):
        path = writer(ok, out, soft=soft, sweeps=experiment_sweeps)
        if path is not None:
            paths.append(path)
    return paths


def _cell(values, fmt: str = ".4f") -> str:
    mean, se, n = mean_se(values)
    if not n:
        return "—"
    return f"{mean:{fmt}}" if n == 1 else f"{mean:{fmt}} ± {se:{fmt}}"


def _methods_in(records) -> list[str]:
    have = {r["config"].get("method") for r in records}
    return [m for m in METHODS if m in have]


def _table_violations(ok, out: Path, *, soft: bool, **_) -> Path | None:
    """Table 7.2: CVR, CVVR, ACVV per method, capacity and transitivity, over the deformation
    and range sweeps (discrete output; soft output too when stored)."""
    rows = [r for r in ok if r["sweep"] in ("deformation", "range")]
    if not rows:
        return None
    lines = ["# Table 7.2: constraint violations (mean ± standard error over the trials of the "
             "deformation and range sweeps)", ""]
    outputs = [("discrete output (the pairwise maps each method returns)", "")]
    if soft:
        outputs.append(("soft output (`res.info['soft']`: the pairwise stage's last soft "
                        "matrices, sub-doubly stochastic; online methods: the synchronized "
                        "iterates; offline methods and RRWM: the unsynchronized pairwise "
                        "RRWM solutions, hence equal)", "soft_"))
    else:
        lines += ["The results store no soft matrices: only the discrete outputs are measured "
                  "(RRWM's are the unsynchronized pairwise maps).", ""]
    for title, prefix in outputs:
        lines += [f"## {title}", "",
                  "| method | " + " | ".join(VIOLATIONS) + " | trials |",
                  "|---|" + "---|" * (len(VIOLATIONS) + 1)]
        for m in _methods_in(rows):
            sub = [r["metrics"] for r in rows if r["config"]["method"] == m]
            cells = [_cell([s.get(prefix + v) for s in sub], ".3g") for v in VIOLATIONS]
            lines.append(f"| {m} | " + " | ".join(cells) + f" | {len(sub)} |")
        lines.append("")
    path = out / "table_7_2.md"
    path.write_text("\n".join(lines))
    return path


def _paired(ok, method: str, other: str, metric: str = "f1") -> dict:
    """``{problem: (metric of method, metric of other)}`` over the problems both solved (the
    runner gives every method of a trial the same problem)."""
    def key(r):
        return (r["sweep"], _problem_key(r["config"]), r["trial"])

    a = {key(r): r["metrics"].get(metric) for r in ok if r["config"]["method"] == method}
    b = {key(r): r["metrics"].get(metric) for r in ok if r["config"]["method"] == other}
    return {k: (a[k], b[k]) for k in a if k in b and a[k] is not None and b[k] is not None}


def _problem_key(config: dict) -> str:
    """The configuration without its method (the problem's key), as a sorted JSON string."""
    import json

    return json.dumps({k: v for k, v in config.items() if k != "method"}, sort_keys=True,
                      default=str)


def _table_universe(ok, out: Path, *, sweeps, **_) -> Path | None:
    """Universe estimation per sweep and method; F1 when right / wrong; the paired F1 loss of
    S-RRWM against S-RRWM told the universe size, on the trials where the estimate is wrong."""
    rows = [r for r in ok if math.isfinite(r["metrics"].get("universe_ok", math.nan))]
    if not rows:
        return None
    have = {r["sweep"] for r in rows}
    sweeps = [sw.name for sw in sweeps if sw.name in have]
    lines = ["# Universe size: estimated vs true", "",
             "True size: the universe nodes kept by at least one graph (d, or fewer when a node "
             "was dropped by every graph). `S-RRWM known d` is told it; the dummy baselines "
             "use the largest graph's size. Paired loss: mean F1 of `S-RRWM known d` minus "
             "`S-RRWM`'s on the same problems where `S-RRWM`'s estimate is wrong.", "",
             "| sweep | method | trials | estimate = truth | mean estimate − truth | "
             "F1 when right | F1 when wrong | paired F1 loss when wrong |",
             "|---|---|---|---|---|---|---|---|"]
    for name in [*sweeps, "all partial-size sweeps"]:
        sub = ([r for r in rows if r["sweep"] == name] if name in sweeps
               else [r for r in rows if r["sweep"] in PARTIAL_SWEEPS])
        if not sub:
            continue
        for m in _methods_in(sub):
            ms = [r for r in sub if r["config"]["method"] == m]
            okv = [r["metrics"]["universe_ok"] for r in ms]
            right = [r["metrics"]["f1"] for r in ms if r["metrics"]["universe_ok"] == 1.0]
            wrong = [r for r in ms if r["metrics"]["universe_ok"] == 0.0]
            loss = "—"
            if m == "S-RRWM" and wrong:
                pairs = _paired(wrong + [r for r in sub
                                         if r["config"]["method"] == "S-RRWM known d"],
                                "S-RRWM known d", "S-RRWM")
                loss = _cell([a - b for a, b in pairs.values()], ".4f") if pairs else "—"
            lines.append(
                f"| {name} | {m} | {len(ms)} | {100 * np.mean(okv):.1f} % | "
                f"{_cell([r['metrics']['universe_error'] for r in ms], '.2f')} | "
                f"{_cell(right)} | {_cell([r['metrics']['f1'] for r in wrong])} | {loss} |")
    path = out / "table_universe.md"
    path.write_text("\n".join(lines) + "\n")
    return path


def _table_cmu(ok, out: Path, **_) -> Path | None:
    """The CMU House partial point: F1, precision, recall, universe, violations, time."""
    rows = [r for r in ok if r["sweep"] == "cmu"]
    if not rows:
        return None
    c = rows[0]["config"]
    cols = ("f1", "precision", "recall", "n_universe", "universe_ok", "transitivity_cvr",
            "capacity_cvr", "seconds")
    lines = [f"# CMU partial: {c['sequence']}, {c['n_frames']} frames spread over the sequence, "
             f"each keeping {c['keep_low']}-{c['keep_high']} landmarks, node orders shuffled",
             "", "Mean ± standard error over the trials (random first frame and kept landmarks).",
             "", "| method | " + " | ".join(cols) + " | trials |",
             "|---|" + "---|" * (len(cols) + 1)]
    for m in _methods_in(rows):
        sub = [r["metrics"] for r in rows if r["config"]["method"] == m]
        cells = [_cell([s.get(k) for s in sub], ".3g" if k == "seconds" else ".4f")
                 for k in cols]
        lines.append(f"| {m} | " + " | ".join(cells) + f" | {len(sub)} |")
    path = out / "table_cmu.md"
    path.write_text("\n".join(lines) + "\n")
    return path


def _table_targets(ok, out: Path, *, sweeps, **_) -> Path | None:
    """Issue #11's targets, checked on the stored trials."""
    if not ok:
        return None
    lines = ["# Targets of issue #11 on these trials", ""]
    # 1. universe beats dummies in F1 at every point of every sweep
    lines += ["## Universe vs dummy nodes (mean F1 per point)", "",
              "| sweep | value | " + " | ".join(f"{a} vs {b}" for a, b in DUMMY_PAIRS.items())
              + " |", "|---|---|" + "---|" * len(DUMMY_PAIRS)]
    tally = {"✓": 0, "=": 0, "✗": 0}
    variables = {sw.name: sw.variable for sw in sweeps}
    points = [(sw.name, value_label(v)) for sw in sweeps for v in sw.values]
    for sweep, value in points:
        cells = []
        for a, b in DUMMY_PAIRS.items():
            fa = mean_se(r["metrics"].get("f1") for r in ok if r["sweep"] == sweep
                         and _value(r, variables) == value and r["config"]["method"] == a)[0]
            fb = mean_se(r["metrics"].get("f1") for r in ok if r["sweep"] == sweep
                         and _value(r, variables) == value and r["config"]["method"] == b)[0]
            if math.isfinite(fa) and math.isfinite(fb):
                mark = "=" if abs(fa - fb) <= 1e-9 else "✓" if fa > fb else "✗"
                tally[mark] += 1
                cells.append(f"{fa:.4f} vs {fb:.4f} {mark}")
            else:
                cells.append("—")
        if any(c != "—" for c in cells):
            lines.append(f"| {sweep} | {value} | " + " | ".join(cells) + " |")
    lines += ["", f"Universe better (✓) at {tally['✓']}, equal (=) at {tally['=']}, worse "
              f"(✗) at {tally['✗']} (point, pair) comparisons. With graphs of equal size "
              "(p_keep = 1) the two methods coincide (nothing to pad).", ""]
    # 2. synchronized discrete outputs violate nothing
    sync = [r for r in ok if r["config"]["method"] in SYNCHRONIZED]
    worst = {v: max((r["metrics"].get(v, 0.0) for r in sync), default=math.nan)
             for v in ("capacity_cvr", "transitivity_cvr")}
    lines += ["## Constraint violations of the synchronized discrete outputs", "",
              f"Largest capacity CVR {worst['capacity_cvr']:.3g}, largest transitivity CVR "
              f"{worst['transitivity_cvr']:.3g} over {len(sync)} trials (target: exactly 0).",
              ""]
    # 3. universe estimate on the partial-size sweeps
    est = [r for r in ok if r["sweep"] in PARTIAL_SWEEPS and r["config"]["method"] == "S-RRWM"]
    if est:
        base = next((dict(sw.base) for sw in sweeps if sw.name == "deformation"), {})
        default = [r for r in est if all(r["config"].get(k) == v for k, v in base.items())]
        frac = np.mean([r["metrics"]["universe_ok"] for r in est])
        lines += ["## Universe size estimated by S-RRWM (n_universe=None)", "",
                  f"Equal to the truth on {100 * frac:.1f} % of {len(est)} trials of the "
                  f"sweeps {', '.join(PARTIAL_SWEEPS)} (target: >= 90 %; the F1 lost when "
                  "wrong: `table_universe.md`)"
                  + (f"; at the default point ({len(default)} trials of these sweeps): "
                     f"{100 * np.mean([r['metrics']['universe_ok'] for r in default]):.1f} %."
                     if default else "."), ""]
    # 4. CMU partial
    cmu = [r for r in ok if r["sweep"] == "cmu" and r["config"]["method"] in SYNCHRONIZED]
    if cmu:
        lines += ["## CMU partial (target: F1 >= 0.95 with default settings, universe 30, "
                  "consistent)", "",
                  "`match_collection`'s default `verify='auto'` verifies graphs of different "
                  "sizes with 2-d points (each pair: an affine map or a homography, the better "
                  "supported): `S-RRWM verified A/H` is the call with default settings (the "
                  "other A/H line: the defaults of its solver and mode); `verified` lines "
                  "verify with an affine map only, the other lines pass `verify=None`.", "",
                  "| method | F1 | universe = truth | transitivity CVR |", "|---|---|---|---|"]
        for m in _methods_in(cmu):
            sub = [r["metrics"] for r in cmu if r["config"]["method"] == m]
            label = f"{m} (**defaults**)" if m == DEFAULT_METHOD else m
            lines.append(f"| {label} | {_cell([s['f1'] for s in sub])} | "
                         f"{100 * np.mean([s['universe_ok'] for s in sub]):.0f} % | "
                         f"{max(s['transitivity_cvr'] for s in sub):.3g} |")
        lines.append("")
    path = out / "table_targets.md"
    path.write_text("\n".join(lines))
    return path


def _value(record, variables: dict) -> str:
    """The swept value of a record, as written in the tables."""
    var = variables.get(record["sweep"])
    return value_label(record["config"].get(var)) if var else ""
