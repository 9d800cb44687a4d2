"""Transitive assignment kernels vs baselines on TU graph sets (thesis Tables 4.2, 4.3, §4.5).

Data sets: MUTAG, PTC_MR, ENZYMES, NCI1 and PPI from ``data_home()/tu``
(:func:`transync.datasets.load_tu`), or any TU folder given as ``data`` (``--data PATH``: a TU
folder, a folder of TU folders, or TU names ``NAME,NAME`` in the data home). A data set is keyed
by its name and a fingerprint of its files' contents (``MUTAG@1a2b3c4d``), never by its path:
moving the data does not invalidate stored trials, changing a file does.

Kernels (:data:`KERNELS`): the transitive assignment kernel ``TAK-*``
(:class:`transync.kernels.TransitiveAssignmentKernel`'s stages: HKS features, pairwise RRWM,
orthogonal synchronization, linear / Gaussian / relaxed slot kernel; ``TAK-spec`` synchronizes
spectrally, ``TAK-node`` matches with the node-only assignment, the fast ablation; the
``-k10`` variants match each graph only to its 10 nearest graphs plus a spanning tree, the view
graph of ``n_neighbors=10``, and run on ENZYMES, PPI and NCI1 -- on NCI1 instead of the
all-pairs variants; the ``-bag5`` variants average the kernels of 5 synchronizations of the same
matches, ``n_alignments=5``), the
same linear and Gaussian kernels on the unsynchronized pairwise RRWM maps (``NT-lin``,
``NT-gauss``: non-transitive, the thesis's "HKS + RRWM" rows, from TAK-lin's cached matching;
:func:`transync.kernels.pairwise_assignment_kernel`), the
non-transitive HKS optimal-assignment kernel (``HKS-OA``), the HKS mean embedding
(``HKS-mean``), GraKeL's Weisfeiler-Lehman subtree (``WL``), WL optimal assignment (``WL-OA``)
and shortest path (``SP``), the labelled geometric random walk (``RW``, lambda = 0.01, solved
exactly: :func:`transync.kernels.random_walk_kernel`) and the exact 3-graphlet kernel
(``graphlet-3``). Every Gram matrix is cosine-normalized.

Stages, each cached so that an interrupted run loses at most the trials in flight:

1. *data*: load, prune by size (:func:`transync.kernels.prune_by_size`, the same kept graphs for
   every kernel; rule in ``table_4_2.md``);
2. *Gram*: one Gram matrix per (data set, kernel, parameters), written to
   ``CACHE/<set>@<fingerprint>/gram-*.npz`` (temporary file, then rename: a crash never leaves
   half a file) with its eigenvalues and timings; the TAK variants share one cached pairwise run
   (``pairwise-*.npz``) and one synchronization per method (``sync-*.npz``). ``CACHE`` is
   ``OUT/cache`` when the output folder is known (``build(out=...)``), else
   ``<user cache>/transync/kernels`` (content-keyed, so sharing it between runs is safe);
3. *evaluation*: one stored trial per (data set, kernel, repetition): a stratified 10-fold
   C-SVM cross-validation (:func:`transync.kernels.repeated_cv`, C chosen by an inner 3-fold CV
   on the training folds), with folds drawn from the repetition alone, identical for every
   kernel of a data set.

Sweeps: ``table`` (every kernel on every data set), ``universe`` and ``scales`` (§4.5: the main
TAK variant with ``n + k`` universe slots, k in {0, 5, 10, 20}, and with T in {2, 4, 6, 10, 16}
HKS scales, on MUTAG and PTC_MR). Besides ``summary.csv`` / ``summary.md`` and the standard
plot, a run writes ``table_4_2.md`` (accuracy, mean ± std over repetitions, best in bold; data
sets and pruning; Gram times), ``table_4_3.md`` (paired t-tests of every TAK variant against
every baseline), ``psd.md`` and ``spectra.png`` (eigenvalues of every Gram matrix; kept in
``spectra.npz`` so that a later finish without the Gram cache does not lose them) and
``dimensionality.png``.

``quick``: MUTAG only, node-only matcher, 2 repetitions, six kernels, no §4.5 sweeps (about
half a minute, most of it the orthogonal synchronization of 188 graphs).
"""

from __future__ import annotations

import contextlib
import dataclasses
import functools
import hashlib
import inspect
import json
import os
import re
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .._validation import check_int
from ._plot import pyplot
from ._runner import Experiment, Sweep

__all__ = ["DATASETS", "KERNELS", "PSD_TOL", "GramEntry", "PreparedSet", "build",
           "compute_gram", "finish", "fingerprint", "kernel_params", "prepare", "prune",
           "resolve_sets", "trial"]

#: the data sets of Tables 4.2 / 4.3, in table order
DATASETS = ("MUTAG", "PTC_MR", "ENZYMES", "NCI1", "PPI")
#: the quick run's data set (PTC_MR's synchronization alone takes longer than a quick run)
QUICK_SETS = ("MUTAG",)
#: data sets of the dimensionality analysis (§4.5)
DIMENSIONALITY_SETS = ("MUTAG", "PTC_MR")
#: extra universe slots and numbers of HKS scales of §4.5
EXTRA_SLOTS = (0, 5, 10, 20)
SCALES = (2, 4, 6, 10, 16)
#: default number of HKS scales (``transync.kernels.HKS_TIMES`` has 10)
N_SCALES = 10

#: kernel name -> parameters; ``family`` picks the code that computes it
KERNELS = {
    "TAK-lin": dict(family="tak", matcher="rrwm", sync="orthogonal", kernel="linear"),
    "TAK-gauss": dict(family="tak", matcher="rrwm", sync="orthogonal", kernel="gaussian"),
    "TAK-relax": dict(family="tak", matcher="rrwm", sync="orthogonal", kernel="relaxed"),
    "TAK-spec": dict(family="tak", matcher="rrwm", sync="spectral", kernel="linear"),
    "TAK-node": dict(family="tak", matcher="node", sync="orthogonal", kernel="linear"),
    "TAK-node-gauss": dict(family="tak", matcher="node", sync="orthogonal", kernel="gaussian"),
    # view graph (n_neighbors = k): each graph matched to its k nearest graphs + a spanning tree
    "TAK-lin-k10": dict(family="tak", matcher="rrwm", sync="orthogonal", kernel="linear",
                        neighbors=10),
    "TAK-gauss-k10": dict(family="tak", matcher="rrwm", sync="orthogonal", kernel="gaussian",
                          neighbors=10),
    "TAK-node-k10": dict(family="tak", matcher="node", sync="orthogonal", kernel="linear",
                         neighbors=10),
    "TAK-node-gauss-k10": dict(family="tak", matcher="node", sync="orthogonal",
                               kernel="gaussian", neighbors=10),
    # ensembles (n_alignments = 5): mean of the Gaussian kernels of 5 synchronizations of the
    # same node-only matches, the first of all matched pairs, 4 of random 70 % subsamples
    "TAK-node-gauss-bag5": dict(family="tak", matcher="node", sync="orthogonal",
                                kernel="gaussian", alignments=5),
    "TAK-node-gauss-k10-bag5": dict(family="tak", matcher="node", sync="orthogonal",
                                    kernel="gaussian", neighbors=10, alignments=5),
    # non-transitive: the same kernels on the pairwise RRWM maps of TAK-lin / TAK-gauss
    "NT-lin": dict(family="pairwise", matcher="rrwm", kernel="linear"),
    "NT-gauss": dict(family="pairwise", matcher="rrwm", kernel="gaussian"),
    "HKS-OA": dict(family="hks-oa"),
    "HKS-mean": dict(family="hks-mean"),
    "WL": dict(family="grakel", name="wl"),
    "WL-OA": dict(family="grakel", name="wl-oa"),
    "SP": dict(family="grakel", name="sp"),
    "RW": dict(family="rw", lamda=1e-2),
    "graphlet-3": dict(family="graphlet3"),
}
#: the full run's kernels (Table 4.2 rows), and the quick run's
FULL_KERNELS = ("TAK-lin", "TAK-gauss", "TAK-relax", "TAK-spec", "TAK-node", "TAK-node-gauss",
                "TAK-node-gauss-bag5", "NT-lin", "NT-gauss", "HKS-OA", "HKS-mean", "WL", "WL-OA",
                "SP", "RW", "graphlet-3")
QUICK_KERNELS = ("TAK-node", "TAK-node-gauss", "HKS-OA", "HKS-mean", "WL", "graphlet-3")
#: view-graph TAK kernels added to the full run on the larger sets (k = 10 nearest graphs)
VIEW_KERNELS = ("TAK-lin-k10", "TAK-gauss-k10", "TAK-node-k10", "TAK-node-gauss-k10")
EXTRA_KERNELS = {"ENZYMES": VIEW_KERNELS, "PPI": VIEW_KERNELS,
                 "NCI1": VIEW_KERNELS + ("TAK-node-gauss-k10-bag5",)}
#: kernels left out of the full run on a data set (too slow there; see docs/kernels.md): on
#: NCI1 (3911 graphs kept, 7.6 million pairs) every all-pairs TAK variant, their
#: non-transitive counterparts and the random walk, GraKeL's WL-OA (its Gram matrix did not
#: finish in 30 CPU-min, 4.1 GB, on this machine), and SP, graphlet-3 and TAK-gauss-k10 (not
#: among the issue's comparisons; one nested 10-fold CV repetition costs 0.6-4 min per kernel
#: there on this machine); on PPI the random walk, whose lambda = 0.01 is above
#: 1 / rho_max^2 = 6.6e-4 there (the walk series diverges)
SKIP = {"NCI1": ("RW", "TAK-lin", "TAK-gauss", "TAK-relax", "TAK-spec", "TAK-node",
                 "TAK-node-gauss", "TAK-node-gauss-bag5", "NT-lin", "NT-gauss", "WL-OA", "SP",
                 "graphlet-3", "TAK-gauss-k10"),
        "PPI": ("RW",)}

#: size pruning: graphs with more nodes than max(quantile, FLOOR) of the sizes are dropped
#: (no set is pruned below FLOOR nodes: MUTAG, max 28, keeps every graph), then classes with
#: fewer than MIN_CLASS graphs
PRUNE_QUANTILE = 0.95
PRUNE_FLOOR = 30
MIN_CLASS = 10

_DIM_RE = re.compile(r"^(?P<base>\S+) (?:n\+(?P<extra>\d+)|T=(?P<scales>\d+))$")


def kernel_params(method: str) -> dict:
    """The parameters of ``method``: a key of :data:`KERNELS`, optionally followed by
    `` n+K`` (K extra universe slots) or `` T=T`` (T HKS scales) for TAK kernels.

    >>> kernel_params("TAK-node n+5")["extra"]
    5
    >>> kernel_params("HKS-OA")["scales"]
    10
    """
    m = _DIM_RE.match(method)
    base = m["base"] if m else method
    if base not in KERNELS:
        raise ValueError(f"unknown kernel {method!r}; choose from {', '.join(KERNELS)} "
                         "(TAK kernels may add ' n+K' or ' T=T')")
    params = dict(KERNELS[base])
    if params["family"] in ("tak", "pairwise", "hks-oa", "hks-mean"):
        params["scales"] = N_SCALES
    if params["family"] in ("tak", "pairwise"):
        params["extra"] = 0
    if m:
        if params["family"] != "tak":
            raise ValueError(f"{method!r}: ' n+K' and ' T=T' apply to TAK kernels only")
        if m["extra"] is not None:
            params["extra"] = int(m["extra"])
        else:
            params["scales"] = int(m["scales"])
            if params["scales"] < 1:
                raise ValueError(f"{method!r}: the number of HKS scales must be >= 1")
    return params


# --------------------------------------------------------------------------- data sets

def _tu_prefix(folder: Path) -> str | None:
    hits = sorted(folder.glob("*_A.txt"))
    return hits[0].name[:-len("_A.txt")] if len(hits) == 1 else None


def resolve_sets(data=None, sets=None) -> dict[str, Path]:
    """Data-set name -> TU folder.

    ``data``: None (the data home's ``tu`` folder), a TU folder (holding one ``*_A.txt``), a
    folder of TU folders, or names ``"NAME,NAME"`` of sets in the data home. ``sets`` (names,
    or one comma-separated string) selects among them; default: all found (:data:`DATASETS`
    order first).

    Raises
    ------
    FileNotFoundError
        A folder or a named set does not exist (the message names it and what was looked at).
    ValueError
        ``sets`` names a set that is not there, or a folder holds no TU set.
    """
    from ..datasets import data_home

    names = None
    if data is not None and not Path(str(data)).expanduser().exists() and \
            re.fullmatch(r"[\w.-]+(,[\w.-]+)*", str(data)):
        names, data = str(data).split(","), None
    if data is None:
        home = data_home(subfolder="tu")
        found = {p.name: p for p in sorted(home.iterdir()) if p.is_dir() and _tu_prefix(p)}
        if names is not None:
            missing = [n for n in names if n not in found]
            if missing:
                raise FileNotFoundError(
                    f"{', '.join(map(repr, missing))}: not a folder, and no such TU set in "
                    f"{home} (found: {', '.join(found) or 'none'}); pass a TU folder with "
                    "--data PATH or set TRANSYNC_DATA")
            found = {n: found[n] for n in names}
    else:
        root = Path(data).expanduser()
        if not root.is_dir():
            what = "is a file, not a folder" if root.exists() else "does not exist"
            raise FileNotFoundError(f"the data folder {root} {what} (expected a TU "
                                    "folder or a folder of TU folders)")
        prefix = _tu_prefix(root)
        if prefix is not None:
            found = {prefix: root}
        else:
            found = {p.name: p for p in sorted(root.iterdir())
                     if p.is_dir() and _tu_prefix(p)}
            if not found:
                raise ValueError(f"{root} holds no TU data set: expected a folder with one "
                                 "DS_A.txt (with DS_graph_indicator.txt, DS_graph_labels.txt) "
                                 "or a folder of such folders")
    if sets is not None:
        want = [s.strip() for s in (sets.split(",") if isinstance(sets, str) else list(sets))]
        want = [s for s in want if s]
        if not want:
            raise ValueError(f"`sets` (--sets) must name at least one data set, got {sets!r}; "
                             f"available: {', '.join(found)}")
        missing = [s for s in want if s not in found]
        if missing:
            raise ValueError(f"`sets`: {', '.join(map(repr, missing))} not found; available: "
                             f"{', '.join(found)}")
        found = {s: found[s] for s in want}
    order = [n for n in DATASETS if n in found] + [n for n in found if n not in DATASETS]
    return {n: found[n] for n in order}


def fingerprint(folder) -> str:
    """First 8 hex digits of a SHA-256 over the names and contents of the TU files in
    ``folder`` (``DS_*.txt``; README and manifest files excluded)."""
    folder = Path(folder)
    prefix = _tu_prefix(folder)
    if prefix is None:
        raise ValueError(f"{folder} is not a TU folder (expected exactly one *_A.txt)")
    h = hashlib.sha256()
    for p in sorted(folder.glob(f"{prefix}_*.txt")):
        h.update(p.name.encode() + b"\0")
        with open(p, "rb") as fh:
            for block in iter(lambda: fh.read(1 << 20), b""):
                h.update(block)
    return h.hexdigest()[:8]


@dataclass(frozen=True)
class PreparedSet:
    """A loaded, size-pruned TU set: the graphs every kernel of the experiment sees."""

    name: str
    key: str                    #: ``name@fingerprint``
    graphs: tuple
    y: np.ndarray
    kept: np.ndarray            #: indices of the kept graphs in the file
    rule: str                   #: the pruning rule and its counts
    n_total: int
    has_node_labels: bool

    @property
    def sizes(self) -> np.ndarray:
        return np.array([g.n_nodes for g in self.graphs])


def prune(sizes, y) -> tuple[np.ndarray, str]:
    """The experiment's pruning: :func:`transync.kernels.prune_by_size` with the cap
    ``max(quantile 0.95 of the sizes, 30)`` and classes of at least 10 graphs."""
    from ..kernels import prune_by_size

    sizes = np.asarray(sizes)
    cap = int(max(np.floor(np.quantile(sizes, PRUNE_QUANTILE)), PRUNE_FLOOR))
    keep, rule = prune_by_size(sizes, y, quantile=None, max_nodes=cap,
                               min_class_size=MIN_CLASS)
    rule = (f"cap = max(floor(q{PRUNE_QUANTILE:g} of sizes), {PRUNE_FLOOR}) = {cap} nodes; "
            + rule)
    return np.asarray(keep), rule


@functools.lru_cache(maxsize=4)
def prepare(path, key: str | None = None) -> PreparedSet:
    """Load the TU folder ``path`` and prune it (:func:`prune`); cached per process."""
    from ..datasets import load_tu

    path = Path(path)
    ds = load_tu(path)
    key = key or f"{ds.name}@{fingerprint(path)}"
    keep, rule = prune(ds.sizes, ds.y)
    sub = ds.subset(keep)
    return PreparedSet(name=ds.name, key=key, graphs=tuple(sub.graphs), y=np.asarray(sub.y),
                       kept=keep, rule=rule, n_total=len(ds), has_node_labels=ds.has_node_labels)


# --------------------------------------------------------------------------- disk cache

#: Version of the kernels' computations in the cache keys: bump it whenever a change of
#: ``transync.kernels`` changes a Gram matrix, so that stale cached entries are not reused.
#: 2: refined synchronization, cross-label matches dropped, exact spectral placement.
#: 3: pairs cut into chunks by work, largest first (near-ties of RRWM / SM may fall otherwise).
#: 4: node affinities of features equal up to rounding exactly 1 (2026-11-27), the spectral
#: rounding's first prototype fixed by the rows' norms, and for a universe above the largest
#: graph the eigengap's columns tried in the rounding (2026-11-28).
#: 5: every graph matched and synchronized in its canonical node order (2026-11-28).
#: 6: pairwise chunks of 8 MiB (RRWM's near-ties fall otherwise) and the matrix-free
#: eigensolver's wider, deeper Krylov blocks after slow restarts (other eigenvectors within the
#: same tolerance, so other alignments on noisy sets) (2026-11-29).
#: 7: RRWM's adjacency products as CSR products (other rounding: ties between equal-score
#: matchings fall otherwise) (2026-11-29).
CACHE_VERSION = 7


def _hash(obj) -> str:
    blob = json.dumps({"v": CACHE_VERSION, "obj": obj}, sort_keys=True, default=str)
    return hashlib.sha1(blob.encode()).hexdigest()[:12]


def _slug(text: str) -> str:
    return re.sub(r"[^\w.-]+", "_", text)


@contextlib.contextmanager
def _file_lock(path: Path):
    """Exclusive lock on ``.locks/<name>.lock`` beside ``path``: processes computing the same
    cache entry wait for the first (the lock files stay: removing them would race)."""
    lock = path.parent / ".locks" / (path.name + ".lock")
    lock.parent.mkdir(parents=True, exist_ok=True)
    with open(lock, "a+") as fh:
        try:
            import fcntl
        except ImportError:  # pragma: no cover - Windows: no lock, at worst computed twice
            yield
            return
        fcntl.lockf(fh.fileno(), fcntl.LOCK_EX)
        try:
            yield
        finally:
            fcntl.lockf(fh.fileno(), fcntl.LOCK_UN)


def save_npz(path, **arrays) -> Path:
    """``np.savez`` into a temporary file beside ``path``, then rename it to ``path``: a crash
    leaves the old file or none, never half of one."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    try:
        with open(tmp, "wb") as fh:
            np.savez(fh, **arrays)
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, path)
    finally:
        with contextlib.suppress(OSError):
            tmp.unlink()
    return path


def _load_npz(path: Path) -> dict | None:
    """The arrays stored at ``path``, or None when it is missing or unreadable."""
    if not path.exists():
        return None
    try:
        with np.load(path, allow_pickle=False) as z:
            return {k: z[k] for k in z.files}
    except (OSError, ValueError, EOFError):     # unreadable: computed again over it
        return None


def _cached(path: Path, compute) -> dict:
    """``dict`` of arrays stored at ``path``, computed (and stored) on first use."""
    with _file_lock(path):
        arrays = _load_npz(path)
        if arrays is None:
            arrays = compute()
            save_npz(path, **arrays)
        return arrays


def _rss_mb() -> float:
    """Resident set size of this process now (MB; Linux ``/proc``), else its peak so far."""
    try:
        with open("/proc/self/statm") as fh:
            return int(fh.read().split()[1]) * os.sysconf("SC_PAGE_SIZE") / 2**20
    except (OSError, ValueError, IndexError, AttributeError):  # pragma: no cover - not Linux
        import resource

        peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
        return peak / 2**20 if sys.platform == "darwin" else peak / 2**10


@contextlib.contextmanager
def _peak_rss(interval: float = 0.05):
    """Samples the process's resident memory every ``interval`` s while the block runs; yields
    a dict whose ``"peak"`` (MB, the largest sample, the end included) and ``"base"`` (at the
    start) are set on exit. Allocations shorter than the interval can be missed."""
    import threading

    out = {"base": _rss_mb()}
    peak = [out["base"]]
    stop = threading.Event()

    def watch():
        while not stop.wait(interval):
            peak[0] = max(peak[0], _rss_mb())

    thread = threading.Thread(target=watch, daemon=True)
    thread.start()
    try:
        yield out
    finally:
        stop.set()
        thread.join()
        out["peak"] = max(peak[0], _rss_mb())


@dataclass(frozen=True)
class GramEntry:
    """A cached Gram matrix with its eigenvalues and how long it took."""

    K: np.ndarray
    spectrum: np.ndarray        #: eigenvalues, ascending
    seconds: float              #: computing it, shared stages (pairwise, sync) included
    params: dict = field(default_factory=dict)
    path: Path | None = None
    #: peak resident memory of the process while computing it (MB; NaN: not recorded; for the
    #: TAK variants sharing a cached alignment, the peak of the run that computed it)
    peak_mb: float = float("nan")
    #: CPU time of this process while computing it (s; the machine is shared, so the wall time
    #: ``seconds`` depends on the load; for TAK variants sharing a cached alignment: their own
    #: kernel only, plus the alignment's when it was computed in the same call)
    cpu_seconds: float = float("nan")

    @property
    def min_eig_ratio(self) -> float:
        top = float(np.max(np.abs(self.spectrum))) if self.spectrum.size else 0.0
        return float(self.spectrum[0] / top) if top > 0 else 0.0


def gram_path(cache_dir, key: str, method: str) -> Path:
    """Where the Gram matrix of ``method`` on the data set ``key`` is cached: one folder per
    data set (``name@fingerprint``), one file per kernel and parameters."""
    params = kernel_params(method)
    return Path(cache_dir) / _slug(key) / f"gram-{_slug(method)}-{_hash(params)}.npz"


def compute_gram(prepared: PreparedSet, method: str, cache_dir, *, executor=None,
                 progress: bool = False) -> GramEntry:
    """The Gram matrix of ``method`` on ``prepared``, from ``cache_dir`` or computed and
    stored there (the shared pairwise and synchronization stages of TAK kernels too)."""
    from ..kernels import spectrum

    params = kernel_params(method)
    path = gram_path(cache_dir, prepared.key, method)
    cache = path.parent

    def compute():
        t0, c0 = time.perf_counter(), time.process_time()
        with _peak_rss() as mem:
            K, seconds, shared_peak, cpu = _gram(prepared, params, cache, executor=executor,
                                                 progress=progress)
        if seconds is None:
            seconds = time.perf_counter() - t0
        peak = max(mem["peak"], shared_peak if shared_peak is not None else 0.0)
        cpu = time.process_time() - c0 if cpu is None else cpu   # before the spectrum
        return dict(K=np.asarray(K, dtype=float), spectrum=spectrum(K),
                    seconds=np.float64(seconds), params=np.str_(json.dumps(params)),
                    peak_mb=np.float64(peak), cpu_seconds=np.float64(cpu))

    arrays = _cached(path, compute)
    return GramEntry(K=arrays["K"], spectrum=arrays["spectrum"],
                     seconds=float(arrays["seconds"]), params=json.loads(str(arrays["params"])),
                     path=path, peak_mb=float(arrays.get("peak_mb", np.nan)),
                     cpu_seconds=float(arrays.get("cpu_seconds", np.nan)))


def _times(scales: int) -> np.ndarray:
    """``scales`` HKS times log-spaced over the default grid's range [0.1, 30]."""
    from ..kernels import HKS_TIMES

    return np.logspace(np.log10(HKS_TIMES[0]), np.log10(HKS_TIMES[-1]), scales)


def _gram(prepared: PreparedSet, params: dict, cache: Path, *, executor, progress):
    """(K, seconds, peak_mb, cpu_seconds): the seconds (peak memory, CPU time) of a TAK kernel
    count its cached shared stage as it took when computed; None for the others (measured by
    the caller)."""
    from .. import kernels as kx

    graphs = list(prepared.graphs)
    labels = [g.node_labels for g in graphs] if prepared.has_node_labels else None
    family = params["family"]
    if family == "tak":
        return _tak_gram(prepared, params, cache, executor=executor, progress=progress)
    if family == "pairwise":
        return _pairwise_gram(prepared, params, cache, executor=executor, progress=progress)
    if family in ("hks-oa", "hks-mean"):
        feats = kx.hks_features(graphs, _times(params["scales"]))
        if family == "hks-oa":
            return kx.hks_oa_kernel(feats, node_labels=labels, executor=executor,
                                    progress=progress), None, None, None
        return kx.hks_mean_kernel(feats, node_labels=labels), None, None, None
    if family == "grakel":
        return kx.grakel_kernel(graphs, params["name"]), None, None, None
    if family == "rw":
        return kx.random_walk_kernel(graphs, lamda=params["lamda"], node_labels=labels,
                                     executor=executor, progress=progress), None, None, None
    if family == "graphlet3":
        return kx.graphlet3_kernel(graphs), None, None, None
    raise ValueError(f"unknown kernel family {family!r}")  # pragma: no cover


def _tak_gram(prepared: PreparedSet, params: dict, cache: Path, *, executor, progress):
    """TAK variants from one cached alignment per (matcher, sync, scales, universe).

    The alignment comes from :class:`~transync.kernels.TransitiveAssignmentKernel` (node
    labels used when the set has them; fitted with ``kernel="relaxed"`` so that its relaxed
    embedding is kept); the linear, Gaussian and relaxed Gram matrices are then the public
    stage functions on its fitted slots and features -- equal to the estimator's ``gram_`` for
    that ``kernel``. The pairwise assignments are stored too, and handed to ``fit`` by the
    other synchronization methods when the estimator accepts them
    (``fit(..., assignments=...)``)."""
    from .. import kernels as kx

    al = _alignment(prepared, params, cache, executor=executor, progress=progress)
    if params.get("alignments", 1) > 1:                 # the alignment cached the matching
        return _ensemble_gram(prepared, params, cache)
    t0, c0 = time.perf_counter(), time.process_time()
    feats = _kernel_features(al)
    if params["kernel"] == "relaxed":
        aligned = kx.relaxed_features(feats, al["embedding"])
    else:
        aligned = kx.aligned_features(feats, al["labels"], al["labels"].shape[1])
    K = kx.assignment_kernel(aligned, kernel=params["kernel"])
    peak = float(al["peak_mb"]) if "peak_mb" in al else None
    cpu = float(al["cpu_seconds"]) + time.process_time() - c0 if "cpu_seconds" in al else None
    return K, float(al["seconds"]) + time.perf_counter() - t0, peak, cpu


def _estimator(params: dict, n: int, **options):
    """The :class:`~transync.kernels.TransitiveAssignmentKernel` of the TAK parameters
    ``params`` (matcher, sync, HKS scales, view graph; universe ``n``; seed 0), with
    ``options`` (kernel, ensemble size, executor, progress)."""
    from ..kernels import TransitiveAssignmentKernel

    return TransitiveAssignmentKernel(
        matcher=params["matcher"], sync=params["sync"], times=_times(params["scales"]),
        n_universe=n, n_neighbors=params.get("neighbors"), random_state=0, **options)


def _matching_seconds(pw: dict) -> float:
    """Wall seconds of the pairwise stage of a cached ``pairwise-*.npz``: the fit that wrote it
    minus its synchronization (``sync_seconds``), i.e. HKS, matching and that fit's own kernel
    (seconds, next to the matching's minutes); files written before 2026-11-27 lack
    ``sync_seconds`` and their time includes one orthogonal synchronization."""
    return float(pw["seconds"]) - float(pw.get("sync_seconds", 0.0))


def _ensemble_gram(prepared: PreparedSet, params: dict, cache: Path):
    """An ensemble TAK kernel: ``TransitiveAssignmentKernel(n_alignments=...)`` fitted on the
    cached pairwise maps of ``params`` (its ``gram_``); its time, memory and CPU time are the
    pairwise stage's as it took plus the ensemble's synchronizations and kernels."""
    pw_path, _, n = _cache_paths(prepared, params, cache)
    pw = _load_npz(pw_path)
    if pw is None:                                           # pragma: no cover - a race
        raise RuntimeError(f"the pairwise maps {pw_path} vanished from the cache")
    est = _estimator(params, n, kernel=params["kernel"], n_alignments=int(params["alignments"]))
    t0, c0 = time.perf_counter(), time.process_time()
    with _peak_rss() as mem:
        est.fit(list(prepared.graphs), assignments=pw["assignments"].astype(np.int64))
    seconds = _matching_seconds(pw) + time.perf_counter() - t0
    cpu = float(pw.get("cpu_seconds", np.nan)) + time.process_time() - c0
    return est.gram_, seconds, max(mem["peak"], float(pw.get("peak_mb", 0.0))), cpu


def _kernel_features(al: dict) -> list:
    """The per-graph node features (HKS and label one-hots) stored with an alignment."""
    offsets = al["offsets"]
    return [al["features"][offsets[k]:offsets[k + 1]] for k in range(len(offsets) - 1)]


def _pairwise_gram(prepared: PreparedSet, params: dict, cache: Path, *, executor, progress):
    """A non-transitive kernel (:func:`transync.kernels.pairwise_assignment_kernel`) on the
    stored pairwise maps of the orthogonal alignment of ``params`` (TAK-lin's, whose node
    features it also uses), all pairs in ``triu_indices`` order
    (:func:`transync.kernels.view_graph`'s); its time and memory are the pairwise stage's plus
    its own -- not the synchronization's, which it does not use."""
    from .. import kernels as kx

    if params.get("neighbors") is not None:
        raise ValueError("non-transitive kernels need the maps of all pairs, not a view graph")
    params = dict(params, sync="orthogonal")
    al = _alignment(prepared, params, cache, executor=executor, progress=progress)
    t0, c0 = time.perf_counter(), time.process_time()
    feats = _kernel_features(al)
    pw_path = _cache_paths(prepared, params, cache)[0]
    pw = _load_npz(pw_path)
    if pw is None:                                           # pragma: no cover - a race
        raise RuntimeError(f"the pairwise maps {pw_path} vanished from the cache")
    pairs = np.column_stack(np.triu_indices(len(feats), 1))
    K = kx.pairwise_assignment_kernel(feats, pw["assignments"].astype(np.int64), pairs,
                                      kernel=params["kernel"])
    cpu = float(pw.get("cpu_seconds", np.nan)) + time.process_time() - c0
    return K, _matching_seconds(pw) + time.perf_counter() - t0, \
        float(pw.get("peak_mb", np.nan)), cpu


def _cache_paths(prepared: PreparedSet, params: dict, cache: Path) -> tuple[Path, Path, int]:
    """(pairwise maps, alignment, universe size) of the TAK parameters ``params``."""
    n = int(prepared.sizes.max()) + int(params["extra"])
    pw_params = dict(matcher=params["matcher"], scales=params["scales"], n=n)
    if params.get("neighbors") is not None:        # keys of the all-pairs entries unchanged
        pw_params["neighbors"] = int(params["neighbors"])
    pw_path = cache / f"pairwise-{params['matcher']}-{_hash(pw_params)}.npz"
    al_path = cache / f"alignment-{params['matcher']}-{params['sync']}-" \
                      f"{_hash(dict(pw_params, sync=params['sync']))}.npz"
    return pw_path, al_path, n


def _alignment(prepared: PreparedSet, params: dict, cache: Path, *, executor, progress):
    graphs = list(prepared.graphs)
    pw_path, al_path, n = _cache_paths(prepared, params, cache)

    def fit():
        c0 = time.process_time()
        with _peak_rss() as mem:
            out = _fit()
        out["peak_mb"] = np.float64(max(mem["peak"], float(out.pop("pairwise_peak_mb"))))
        out["cpu_seconds"] = np.float64(time.process_time() - c0
                                        + float(out.pop("pairwise_cpu_seconds")))
        return out

    def _fit():
        est = _estimator(params, n, kernel="relaxed", executor=executor, progress=progress)
        with _file_lock(pw_path):
            stored = _load_npz(pw_path)
            t0 = time.perf_counter()
            pw_peak = pw_cpu = 0.0
            if stored is not None and "assignments" in inspect.signature(est.fit).parameters:
                est.fit(graphs, assignments=stored["assignments"].astype(np.int64))
                seconds = time.perf_counter() - t0 + _matching_seconds(stored)
                pw_peak = float(stored.get("peak_mb", 0.0))
                pw_cpu = float(stored.get("cpu_seconds", np.nan))
            else:
                c0 = time.process_time()
                with _peak_rss() as pm:
                    est.fit(graphs)
                seconds = time.perf_counter() - t0
                a = np.asarray(est.assignments_)
                # the fit's wall time, and its synchronization's share: the pairwise stage
                # is their difference (_matching_seconds); CPU time is not split
                info = est.alignment_.info
                sync_seconds = float(info.get("seconds_total", 0.0)
                                     + info.get("seconds_input", 0.0))
                save_npz(pw_path, assignments=a.astype(np.uint8 if n <= 256 else np.int32),
                         seconds=np.float64(seconds), sync_seconds=np.float64(sync_seconds),
                         peak_mb=np.float64(pm["peak"]),
                         cpu_seconds=np.float64(time.process_time() - c0))
        feats = list(est.kernel_features_)
        return dict(labels=np.asarray(est.labels_),
                    embedding=np.asarray(est.alignment_.embedding),
                    features=np.concatenate(feats),
                    offsets=np.cumsum([0] + [f.shape[0] for f in feats]),
                    seconds=np.float64(seconds), pairwise_peak_mb=np.float64(pw_peak),
                    pairwise_cpu_seconds=np.float64(pw_cpu))

    return _cached(al_path, fit)


# --------------------------------------------------------------------------- trials

def trial(config: dict, rng: np.random.Generator, *, sources: dict, cache_dir) -> dict:
    """One repetition of the cross-validation of one kernel on one data set.

    ``config["dataset"]`` is a key ``name@fingerprint`` of ``sources`` (key -> TU folder);
    the folds come from ``rng``, which the runner derives from the data set and the
    repetition only, so every kernel of a data set sees the same folds.
    """
    from ..kernels import repeated_cv

    key = config["dataset"]
    if key not in sources:
        raise ValueError(f"data set {key!r} is not among this run's sources "
                         f"({', '.join(sources)})")
    prepared = prepare(str(sources[key]), key)
    gram = compute_gram(prepared, config["method"], cache_dir)
    random_state = int(rng.integers(2**31 - 1))
    t0 = time.perf_counter()
    cv = repeated_cv(gram.K, prepared.y, n_splits=int(config["folds"]), n_repeats=1,
                     inner_splits=int(config["inner_folds"]), random_state=random_state)
    accs = np.asarray(cv.accuracies, dtype=float).ravel()
    chosen = np.asarray(cv.chosen_C, dtype=float).ravel()
    out = {"accuracy": float(np.mean(accs)), "gram_seconds": gram.seconds,
           "gram_peak_mb": gram.peak_mb, "gram_cpu_seconds": gram.cpu_seconds,
           "cv_seconds": time.perf_counter() - t0, "min_eig_ratio": gram.min_eig_ratio,
           "n_graphs": float(len(prepared.graphs)),
           # the folds' fingerprint as an exact float (52 bits): pairs repetitions in t-tests
           "folds_id": float(int(cv.fingerprint[:13], 16))}
    out.update({f"fold_{k}": float(a) for k, a in enumerate(accs)})
    out.update({f"C_{k}": float(c) for k, c in enumerate(chosen)})
    return out


@dataclass(frozen=True)
class _TableSweep(Sweep):
    """The table sweep with a kernel list per data set (``per_value``: data-set key -> kernels;
    sets not listed run ``methods``), so that a kernel skipped on one set is not computed there
    because another set runs it."""

    per_value: dict = field(default_factory=dict)

    def configs(self):
        for value, method, config in super().configs():
            if method in self.per_value.get(value, self.methods):
                yield value, method, config


def _default_cache(out) -> Path:
    if out is not None:
        return Path(out) / "cache"
    base = os.environ.get("XDG_CACHE_HOME")
    root = Path(base).expanduser() if base and Path(base).is_absolute() else \
        Path.home() / ".cache"
    return root / "transync" / "kernels"


def build(*, quick: bool = False, data=None, sets=None, out=None, cache_dir=None,
          kernels=None, folds: int = 10, dimensionality: bool | None = None) -> Experiment:
    """Tables 4.2 / 4.3 and the §4.5 analysis on the TU sets of ``data`` (see
    :func:`resolve_sets`; ``sets`` selects by name).

    ``quick``: MUTAG (else the first set found), node-only matcher, 2 repetitions, six
    kernels, no dimensionality sweeps; full: every kernel of :data:`FULL_KERNELS`, 10
    repetitions of 10-fold CV, the §4.5 sweeps on MUTAG and PTC_MR.
    ``out`` (the run's output folder) places the Gram cache in ``out/cache``; ``cache_dir``
    overrides it. ``kernels`` replaces the list of kernels (names of :func:`kernel_params`),
    ``folds`` the number of outer folds; ``dimensionality`` (default: not ``quick``) adds the
    §4.5 sweeps.
    """
    folds = check_int(folds, "folds", minimum=2)
    if kernels is not None:
        kernels = tuple([kernels] if isinstance(kernels, str) else kernels)
        for k in kernels:
            kernel_params(k)
    sources = resolve_sets(data, sets)
    if quick and sets is None:      # MUTAG when present, else the first set found
        picked = [s for s in QUICK_SETS if s in sources] or list(sources)[:1]
        sources = {s: sources[s] for s in picked}
    keys = {f"{name}@{fingerprint(path)}": path for name, path in sources.items()}
    for key, path in keys.items():      # malformed files and empty pruning fail here, once
        prepare(str(path), key)
    cache = Path(cache_dir) if cache_dir is not None else _default_cache(out)
    full = kernels is None and not quick
    if kernels is None:
        kernels = QUICK_KERNELS if quick else FULL_KERNELS
    main = "TAK-node" if quick else "TAK-lin"
    base = dict(folds=folds, inner_folds=3, protocol="C-SVM, C in 10^-3..10^3")
    sweeps = []
    for key in keys:
        name = key.split("@")[0]
        methods = tuple(k for k in kernels if k not in SKIP.get(name, ()) or quick)
        if full:
            methods += tuple(k for k in EXTRA_KERNELS.get(name, ())
                             if k not in methods and k not in SKIP.get(name, ()))
        sweeps.append((key, methods))
    table_sets = [k for k, _ in sweeps]
    methods_all = tuple(dict.fromkeys(m for _, ms in sweeps for m in ms))
    out_sweeps = [_TableSweep(name="table", variable="dataset", values=table_sets,
                              methods=methods_all, base=base,
                              metrics=("accuracy", "gram_seconds"), xlabel="data set",
                              per_value=dict(sweeps))]
    dim_sets = [k for k in keys if k.split("@")[0] in DIMENSIONALITY_SETS]
    if dimensionality is None:
        dimensionality = not quick
    if dim_sets and dimensionality:
        extras, scales = EXTRA_SLOTS, SCALES
        out_sweeps += [
            Sweep(name="universe", variable="dataset", values=dim_sets,
                  methods=tuple(f"{main} n+{e}" for e in extras), base=base,
                  metrics=("accuracy",), xlabel="data set"),
            Sweep(name="scales", variable="dataset", values=dim_sets,
                  methods=tuple(f"{main} T={t}" for t in scales), base=base,
                  metrics=("accuracy",), xlabel="data set")]
    names = ", ".join(k.split("@")[0] for k in keys)
    where = f"Gram cache {cache}"
    return Experiment(
        name="kernels", sweeps=out_sweeps, trials=2 if quick else 10,
        trial=functools.partial(trial, sources={k: str(p) for k, p in keys.items()},
                                cache_dir=str(cache)),
        description=f"{names}; {len(methods_all)} kernels, 10-fold CV ({where})",
        finish=functools.partial(finish, sources={k: str(p) for k, p in keys.items()},
                                 cache_dir=str(cache)))


# --------------------------------------------------------------------------- outputs

def _set_name(key: str) -> str:
    return key.split("@")[0]


def _by(records, sweep: str) -> dict:
    """(data-set key, method) -> {repetition: metrics} of the successful trials of ``sweep``."""
    out: dict = {}
    for r in records:
        if r["sweep"] == sweep and not r["error"]:
            out.setdefault((r["config"]["dataset"], r["config"]["method"]), {})[r["trial"]] = \
                r["metrics"]
    return out


def _set_order(key: str):
    name = _set_name(key)
    return (DATASETS.index(name) if name in DATASETS else len(DATASETS), name)


def _method_order(method: str):
    names = list(KERNELS)
    base = method.split(" ")[0]
    return (names.index(base) if base in names else len(names), method)


def _is_tak(method: str) -> bool:
    return method.startswith("TAK")


def finish(records, summary, out_dir, *, sources: dict, cache_dir) -> list:
    """``table_4_2.md``, ``table_4_3.md``, ``psd.md``, ``spectra.png`` and
    ``dimensionality.png`` from the stored trials (and the cached Gram matrices)."""
    out = Path(out_dir)
    table = _by(records, "table")
    if not table:
        return []
    sets = sorted(dict.fromkeys(k for k, _ in table), key=_set_order)
    methods = sorted(dict.fromkeys(m for _, m in table), key=_method_order)
    paths = [_table_4_2(table, sets, methods, sources, out),
             _table_4_3(table, sets, methods, out)]
    spectra = _spectra(sets, methods, cache_dir, out)
    paths += [_psd(spectra, sets, methods, out), _plot_spectra(spectra, sets, methods, out)]
    dim = _plot_dimensionality(records, out)
    if dim is not None:
        paths.append(dim)
    return paths


def _per_repeat(cell: dict) -> np.ndarray:
    return np.array([cell[t]["accuracy"] for t in sorted(cell)], dtype=float)


def _table_4_2(table, sets, methods, sources, out: Path) -> Path:
    reps = {s: max(len(v) for (k, _m), v in table.items() if k == s) for s in sets}
    lines = ["# Table 4.2: classification accuracy (%), C-SVM on the precomputed kernel", "",
             "Mean ± standard deviation over the repetitions (row *repetitions*: fewer on a "
             "set where the full 10 did not fit this machine's time; see docs/kernels.md) of a "
             "stratified 10-fold "
             "cross-validation (each repetition's accuracy is the mean over its folds; the "
             "standard deviation is that of the repetition means, the field's convention). "
             "C in {10^-3, ..., 10^3} chosen by a 3-fold inner CV on the training folds only; "
             "the folds of a repetition are the same for every kernel of a data set. Best "
             "mean per data set in bold. Every Gram matrix is cosine-normalized.", "",
             "| kernel | " + " | ".join(_set_name(s) for s in sets) + " |",
             "|---|" + "---|" * len(sets),
             "| *repetitions* | " + " | ".join(str(reps[s]) for s in sets) + " |"]
    best = {}
    for s in sets:
        means = [np.mean(_per_repeat(table[(s, m)])) for m in methods if (s, m) in table]
        best[s] = max(means) if means else None
    for m in methods:
        cells = []
        for s in sets:
            if (s, m) not in table:
                cells.append("—")
                continue
            acc = 100 * _per_repeat(table[(s, m)])
            sd = acc.std(ddof=1) if acc.size > 1 else 0.0
            text = f"{acc.mean():.1f} ± {sd:.1f}"
            cells.append(f"**{text}**" if np.isclose(acc.mean(), 100 * best[s]) else text)
        lines.append(f"| {m} | " + " | ".join(cells) + " |")
    lines += ["", "## Data sets after size pruning", "",
              "| data set | fingerprint | graphs | kept | classes | universe n | rule |",
              "|---|---|---|---|---|---|---|"]
    for s in sets:
        if s not in sources:
            continue
        p = prepare(str(sources[s]), s)
        lines.append(f"| {p.name} | {s.split('@')[1]} | {p.n_total} | {len(p.graphs)} | "
                     f"{len(np.unique(p.y))} | {int(p.sizes.max())} | {p.rule} |")
    lines += ["", "## Time to compute each Gram matrix (s, this machine, indicative)", "",
              "The TAK variants sharing one alignment (same matcher and synchronization: "
              "pairwise matching + synchronization, cached) each count its full time plus "
              "their own kernel; the alignment was computed once. Wall seconds, and in "
              "parentheses the process's CPU seconds where recorded (the machine is shared: "
              "wall time depends on its load).", ""]
    lines += _kernel_by_set(methods, sets, table, _time_cell)
    lines += ["", "## Peak memory while computing each Gram matrix (MB, resident, whole process)",
              "", "Largest resident set size of the process sampled every 0.05 s while the Gram "
              "matrix (for TAK: its shared pairwise matching and synchronization) was computed; "
              "it includes the loaded data and the interpreter (about 0.3 GB). —: computed "
              "before memory was recorded.", ""]
    lines += _kernel_by_set(methods, sets, table, _memory_cell)
    path = out / "table_4_2.md"
    path.write_text("\n".join(lines) + "\n")
    return path


def _finite(cell: dict, key: str) -> list[float]:
    vals = [v.get(key) for v in cell.values()]
    return [float(v) for v in vals if v is not None and np.isfinite(v)]


def _time_cell(cell: dict) -> str:
    """Median wall seconds, and in parentheses the median CPU seconds where recorded."""
    cpu = _finite(cell, "gram_cpu_seconds")
    return (f"{np.median([v['gram_seconds'] for v in cell.values()]):.3g}"
            + (f" ({np.median(cpu):.3g})" if cpu else ""))


def _memory_cell(cell: dict) -> str:
    vals = _finite(cell, "gram_peak_mb")
    return f"{np.median(vals):.0f}" if vals else "—"


def _kernel_by_set(methods, sets, table, fmt) -> list[str]:
    """A Markdown table, a row per kernel and a column per data set, of ``fmt(cell)`` (—: no
    record)."""
    lines = ["| kernel | " + " | ".join(_set_name(s) for s in sets) + " |",
             "|---|" + "---|" * len(sets)]
    for m in methods:
        cells = [fmt(table[(s, m)]) if table.get((s, m)) else "—" for s in sets]
        lines.append(f"| {m} | " + " | ".join(cells) + " |")
    return lines


def cv_result(cell: dict, repetitions):
    """A :class:`~transync.kernels.CVResult` assembled from stored trials (repetition ->
    metrics): fold accuracies and chosen C from the ``fold_k`` / ``C_k`` metrics; ``folds``
    holds each repetition's fold fingerprint (``folds_id``, one column) instead of the fold of
    every sample, which is all :func:`~transync.kernels.paired_ttest` compares."""
    from ..kernels import CVResult

    rows = [cell[r] for r in repetitions]
    n_splits = sum(1 for k in rows[0] if k.startswith("fold_"))
    acc = np.array([[m[f"fold_{k}"] for k in range(n_splits)] for m in rows], dtype=float)
    chosen = np.array([[m.get(f"C_{k}", np.nan) for k in range(n_splits)] for m in rows])
    folds = np.array([[int(m["folds_id"])] for m in rows], dtype=np.int64)
    per = acc.mean(axis=1)
    fields = dict(accuracies=acc, per_repeat=per, mean=float(per.mean()), std=float(per.std()),
                  chosen_C=chosen, chosen_kernel=np.zeros(acc.shape, dtype=np.int64),
                  folds=folds, fingerprint=hashlib.sha1(folds.tobytes()).hexdigest()[:16],
                  C_grid=np.unique(chosen[np.isfinite(chosen)]),
                  info={"from": "stored trials"})
    names = {f.name for f in dataclasses.fields(CVResult)}
    return CVResult(**{k: v for k, v in fields.items() if k in names})


def _table_4_3(table, sets, methods, out: Path) -> Path:
    from ..kernels import paired_ttest

    taks = [m for m in methods if _is_tak(m)]
    bases = [m for m in methods if not _is_tak(m)]
    lines = ["# Table 4.3: paired t-tests, TAK variants against the baselines", "",
             "Two-sided paired test on the same folds (:func:`transync.kernels.paired_ttest`, "
             "its default: Nadeau and Bengio's corrected resampled t-test over the fold "
             "differences, which accounts for folds sharing training graphs): p-value and "
             "mean accuracy difference TAK − baseline in points; **bold** = p < 0.05. n/a: "
             "fewer than 2 common repetitions."]
    for s in sets:
        lines += ["", f"## {_set_name(s)}", "",
                  "| TAK \\ baseline | " + " | ".join(bases) + " |",
                  "|---|" + "---|" * len(bases)]
        for t in taks:
            cells = []
            for b in bases:
                A, B = table.get((s, t)), table.get((s, b))
                common = sorted(set(A or ()) & set(B or ()))
                if len(common) < 2:
                    cells.append("n/a")
                    continue
                a, bb = cv_result(A, common), cv_result(B, common)
                diff = 100 * (a.mean - bb.mean)
                if a.fingerprint != bb.fingerprint:
                    cells.append("folds differ")
                    continue
                _t, p = paired_ttest(a, bb)
                text = f"p={p:.2g} ({diff:+.1f})"
                cells.append(f"**{text}**" if p < 0.05 else text)
            lines.append(f"| {t} | " + " | ".join(cells) + " |")
    path = out / "table_4_3.md"
    path.write_text("\n".join(lines) + "\n")
    return path


#: the spectra of every Gram matrix a finish has seen, beside the tables (``set::method`` keys)
SPECTRA_FILE = "spectra.npz"


def _spectra(sets, methods, cache_dir, out_dir=None) -> dict:
    """(set, method) -> eigenvalues of the cached Gram matrix, else the ones kept in
    ``out_dir / SPECTRA_FILE`` by an earlier finish; the file is then updated with every
    spectrum known. A finish without the Gram cache (cleared, or another machine) so keeps the
    spectra it cannot recompute instead of dropping them from psd.md and spectra.png."""
    kept = {}
    store = None if out_dir is None else Path(out_dir) / SPECTRA_FILE
    if store is not None:
        for key, ev in (_load_npz(store) or {}).items():
            s, sep, m = key.partition("::")
            if sep:
                kept[(s, m)] = np.asarray(ev, dtype=float)
    out = {}
    for s in sets:
        for m in methods:
            path = gram_path(cache_dir, s, m)
            if path.exists():
                with contextlib.suppress(OSError, ValueError, KeyError), \
                        np.load(path, allow_pickle=False) as z:
                    out[(s, m)] = np.asarray(z["spectrum"], dtype=float)
            if (s, m) not in out and (s, m) in kept:
                out[(s, m)] = kept[(s, m)]
    if store is not None and out:
        merged = {**kept, **out}
        save_npz(store, **{f"{s}::{m}": ev for (s, m), ev in merged.items()})
    return out


def _ratio(ev: np.ndarray) -> float:
    top = float(np.max(np.abs(ev)))
    return float(ev[0] / top) if top > 0 else 0.0


#: PSD test of the issue: lambda_min >= -PSD_TOL * lambda_max
PSD_TOL = 1e-9


def _psd(spectra, sets, methods, out: Path) -> Path:
    lines = ["# Positive semidefiniteness of the Gram matrices", "",
             f"Smallest over largest eigenvalue λ_min / λ_max of each cosine-normalized Gram "
             f"matrix; PSD when ≥ −{PSD_TOL:g}, marked ✗ otherwise, with the number of "
             "eigenvalues below that threshold and the share of the spectrum's absolute mass "
             "they carry.", "",
             "| kernel | " + " | ".join(_set_name(s) for s in sets) + " |",
             "|---|" + "---|" * len(sets)]
    for m in methods:
        cells = []
        for s in sets:
            ev = spectra.get((s, m))
            if ev is None or not ev.size:
                cells.append("—")
                continue
            r = _ratio(ev)
            top = float(np.max(np.abs(ev)))
            neg = ev < -PSD_TOL * top
            if neg.any():
                mass = float(np.abs(ev[neg]).sum() / np.abs(ev).sum())
                cells.append(f"✗ {r:.2e} ({int(neg.sum())} neg., {100 * mass:.1f}%)")
            else:
                cells.append(f"✓ {r:.1e}")
        lines.append(f"| {m} | " + " | ".join(cells) + " |")
    path = out / "psd.md"
    path.write_text("\n".join(lines) + "\n")
    return path


def _plot_spectra(spectra, sets, methods, out: Path) -> Path:
    plt = pyplot()
    fig, axes = plt.subplots(1, len(sets), figsize=(max(7.0, 3.6 * len(sets) + 2.4), 3.6),
                             squeeze=False)
    cycle = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    styles = {m: (cycle[k % len(cycle)], "-" if _is_tak(m) else "--")
              for k, m in enumerate(methods)}
    for ax, s in zip(axes[0], sets):
        for m in methods:
            ev = spectra.get((s, m))
            if ev is None or not ev.size:
                continue
            top = float(np.max(np.abs(ev)))
            rel = ev / top if top > 0 else ev
            color, ls = styles[m]
            ax.plot(np.arange(1, rel.size + 1) / rel.size, rel, ls, color=color, lw=1.2,
                    label=m)
        ax.set_yscale("symlog", linthresh=1e-6)
        ax.axhline(0, color="k", lw=0.6)
        ax.set_xlabel("eigenvalue rank / N (ascending)")
        ax.set_title(_set_name(s), fontsize=10)
        ax.grid(alpha=0.3)
    axes[0, 0].set_ylabel("λ / λ_max  (symlog; linear in ±1e-6)")
    handles, labels = axes[0, 0].get_legend_handles_labels()
    for ax in axes[0, 1:]:
        for h, lab in zip(*ax.get_legend_handles_labels()):
            if lab not in labels:
                handles.append(h)
                labels.append(lab)
    fig.legend(handles, labels, loc="center right", fontsize=7, frameon=False,
               title="kernel (solid: TAK)", title_fontsize=7)
    fig.suptitle("Eigenvalues of the normalized Gram matrices (below 0: indefinite)",
                 fontsize=10)
    fig.tight_layout(rect=(0, 0, 1 - 2.0 / fig.get_figwidth(), 1))
    path = out / "spectra.png"
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return path


def _plot_dimensionality(records, out: Path) -> Path | None:
    panels = []
    for sweep, xlabel in (("universe", "extra universe slots k (universe n + k)"),
                          ("scales", "number of HKS scales T")):
        cells = _by(records, sweep)
        if cells:
            panels.append((sweep, xlabel, cells))
    if not panels:
        return None
    plt = pyplot()
    fig, axes = plt.subplots(1, len(panels), figsize=(4.6 * len(panels) + 1.6, 3.5),
                             squeeze=False)
    for ax, (sweep, xlabel, cells) in zip(axes[0], panels):
        for s in dict.fromkeys(k for k, _ in cells):
            pts = []
            for (key, method), cell in cells.items():
                if key != s:
                    continue
                p = kernel_params(method)
                x = p["extra"] if sweep == "universe" else p["scales"]
                acc = 100 * _per_repeat(cell)
                pts.append((x, acc.mean(), acc.std(ddof=1) if acc.size > 1 else 0.0))
            pts.sort()
            x, m, sd = (np.array(v) for v in zip(*pts))
            ax.errorbar(x, m, yerr=sd, marker="o", ms=4, capsize=3, label=_set_name(s))
        ax.set_xlabel(xlabel)
        ax.set_ylabel("accuracy (%)")
        ax.grid(alpha=0.3)
        method = next(iter(cells))[1].split(" ")[0]
        ax.set_title(f"{method}: {'universe dimension' if sweep == 'universe' else 'HKS scales'}",
                     fontsize=10)
    handles, labels = axes[0, 0].get_legend_handles_labels()
    fig.legend(handles, labels, loc="center right", fontsize=8, frameon=False,
               title="data set", title_fontsize=8)
    fig.suptitle("§4.5 dimensionality: mean ± std over CV repetitions", fontsize=10)
    fig.tight_layout(rect=(0, 0, 1 - 1.4 / fig.get_figwidth(), 1))
    path = out / "dimensionality.png"
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return path

