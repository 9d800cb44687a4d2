"""Multi-graph matching on a CMU House / Hotel landmark sequence (thesis Table 6.1).

Every trial draws ``n_frames`` frames spread over the sequence at a fixed frame ``gap``
(positions ``offset, offset + gap, ...``, with a random ``offset``), builds Delaunay graphs on
their landmarks with node orders shuffled
(:meth:`transync.datasets.LandmarkSequence.graphs`) and matches them with one of the seven
methods of Table 6.1 (``GA``, ``S-GA``, ``RRWM``, ``S-RRWM``, ``PF``, ``S-PF``, ``CAO``; see
:mod:`transync.experiments.multigraph`) on the length + angle edge affinity of Yan et al.
(:data:`transync.datasets.LANDMARK_AFFINITY`). The sweep runs over several frame gaps, up to
the largest that spreads ``n_frames`` frames over the whole sequence.

Metrics as in the ``multigraph`` experiment: ``accuracy`` (mean pairwise accuracy against the
landmark identities), ``objective`` (affinity score relative to the ground truth's),
``consistency`` of the output, ``seconds``.

The data folder (``build(data=...)``, ``transync experiment cmu --data PATH``) is any folder in
the CMU layout (:func:`transync.datasets.load_cmu_sequence`); default
``data_home() / "cmu-house"`` (``TRANSYNC_DATA``). Besides the standard plot, a run writes
``table_6_1.md`` (mean accuracy ± standard error per method and gap) and ``table_6_1.png``.
"""

from __future__ import annotations

import functools
import hashlib
from pathlib import Path

import numpy as np

from ..matching import gaussian_edge_affinity
from ._plot import pyplot
from ._runner import Experiment, Sweep, mean_se
from .multigraph import collection_metrics, run_method

#: the seven methods of Table 6.1 (keys of :data:`transync.experiments.multigraph.METHODS`)
METHODS = ("GA", "S-GA", "RRWM", "S-RRWM", "PF", "S-PF", "CAO")
METRICS = ("accuracy", "objective", "consistency", "seconds")


@functools.lru_cache(maxsize=8)
def _load(path: str):
    """The sequence of ``path``, read once per process (trials run in worker processes)."""
    return load_sequence(path)


def load_sequence(data=None):
    """The CMU-layout sequence of ``data`` (default: ``TRANSYNC_DATA``'s ``cmu-house``).

    Raises ``FileNotFoundError`` with one line naming the folder and ``TRANSYNC_DATA`` when
    the folder (or its ``label/``) is missing; ``ValueError`` for malformed label files and
    for a sequence the experiments cannot match (fewer than 2 landmarks per frame, or a frame
    whose landmarks all coincide), before any trial runs.
    """
    from ..datasets import data_home, load_cmu_sequence

    try:
        folder = (data_home(subfolder="cmu-house") if data is None
                  else Path(data).expanduser())
        seq = load_cmu_sequence(folder)
    except (FileNotFoundError, NotADirectoryError) as exc:
        where = "the default CMU House folder" if data is None else f"the data folder {data}"
        raise FileNotFoundError(
            f"cannot read a CMU-layout sequence from {where} ({' '.join(str(exc).split())}); "
            "pass a folder in the CMU layout (`label/<name><N>` files; `--data PATH` on the "
            "command line) or set TRANSYNC_DATA to a folder holding `cmu-house`") from None
    if seq.n_landmarks < 2:
        raise ValueError(f"the sequence in {folder} has {seq.n_landmarks} landmark per frame; "
                         "matching its frames needs at least 2")
    flat = np.flatnonzero(np.all(seq.points == seq.points[:, :1], axis=(1, 2)))
    if flat.size:       # no graph, no normalization: every trial drawing it would fail
        f = int(seq.frames[flat[0]])
        raise ValueError(f"the sequence in {folder}: all {seq.n_landmarks} landmarks of frame {f} "
                         f"(label file number {f + 1}) coincide; matching needs distinct points")
    return seq


def draw_frames(data, config: dict, n: int, gap: int, rng: np.random.Generator):
    """The sequence in ``data`` (checked against ``config["fingerprint"]`` when recorded) and
    ``n`` frame numbers ``gap`` apart from a random start: ``(sequence, frames)``."""
    seq = _load(data)
    if config.get("fingerprint") not in (None, sequence_fingerprint(seq)):
        raise ValueError(f"the sequence in {data} is not the one this experiment was built on "
                         "(its landmarks changed); rebuild the experiment")
    span = gap * (n - 1)
    if span > seq.n_frames - 1:
        raise ValueError(f"{n} frames {gap} apart need {span + 1} frames, the sequence "
                         f"{seq.name!r} has {seq.n_frames}")
    offset = int(rng.integers(0, seq.n_frames - span))
    return seq, seq.frames[offset + gap * np.arange(n)].tolist()


def trial(config: dict, rng: np.random.Generator, *, data: str) -> dict:
    """One draw of ``n_frames`` frames at ``gap`` apart, one method of :data:`METHODS`.

    ``data`` is the sequence's folder; it is bound by :func:`build` and is not part of the
    stored configuration (which holds the sequence's content fingerprint instead), so moving
    the data folder does not invalidate stored trials.
    """
    from ..datasets import LANDMARK_AFFINITY

    seq, frames = draw_frames(data, config, int(config["n_frames"]), int(config["gap"]), rng)
    problem = seq.graphs(frames, shuffle=True, rng=rng)
    affinity = functools.partial(gaussian_edge_affinity, **LANDMARK_AFFINITY)
    res, seconds = run_method(config["method"], problem.graphs, affinity, rng)
    out = collection_metrics(res, problem, affinity, seconds)
    out["first_frame"] = float(frames[0])
    return out


def sequence_fingerprint(seq) -> str:
    """A short hash of a sequence's landmarks and frame numbers (the stored trials' key)."""
    h = hashlib.sha1(np.ascontiguousarray(seq.points, dtype=np.float64).tobytes())
    h.update(np.ascontiguousarray(seq.frames, dtype=np.int64).tobytes())
    return h.hexdigest()[:16]


def frame_gaps(n_sequence: int, n_frames: int, *, count: int = 5) -> list[int]:
    """Up to ``count`` frame gaps from 1 to the largest that fits ``n_frames`` frames into a
    sequence of ``n_sequence`` frames (spread over the whole sequence).

    >>> frame_gaps(111, 20)
    [1, 2, 3, 4, 5]
    >>> frame_gaps(111, 10, count=4)
    [1, 5, 8, 12]
    """
    largest = (n_sequence - 1) // max(n_frames - 1, 1)
    if largest < 1:
        raise ValueError(f"`n_frames` must be at most the sequence's {n_sequence} frames, got "
                         f"{n_frames}")
    return sorted({int(round(g)) for g in np.linspace(1, largest, min(count, largest))})


def build(*, quick: bool = False, data=None) -> Experiment:
    """Table 6.1 on the sequence in ``data`` (a folder in the CMU layout).

    ``quick``: 4 frames, two gaps, two trials (seconds); full: 20 frames (fewer when the
    sequence is short), five gaps, 20 trials.
    """
    seq = load_sequence(data)
    path = str(Path(seq.source).resolve())
    if quick:
        n_frames = min(4, seq.n_frames)
        count, trials = 2, 2
    else:
        n_frames = min(20, seq.n_frames)
        count, trials = 5, 20
    if n_frames < 2:
        raise ValueError(f"the sequence in {path} has {seq.n_frames} frame(s); the cmu "
                         "experiment needs at least 2")
    gaps = frame_gaps(seq.n_frames, n_frames, count=count)
    base = dict(sequence=seq.name, fingerprint=sequence_fingerprint(seq), n_frames=n_frames)
    sweeps = [Sweep(name="gap", variable="gap", values=gaps, methods=METHODS, base=base,
                    metrics=METRICS,
                    xlabel=f"frame gap ({n_frames} frames of {seq.name!r})")]
    return Experiment(name="cmu", sweeps=sweeps, trial=functools.partial(trial, data=path),
                      trials=trials,
                      description=f"{seq.name} ({seq.n_frames} frames, {seq.n_landmarks} "
                                  f"landmarks), {n_frames} frames per trial",
                      finish=functools.partial(finish, title=seq.name))


def finish(records, summary, out_dir, *, title: str) -> list[Path]:
    """``table_6_1.md`` and ``table_6_1.png`` from the stored trials."""
    out = Path(out_dir)
    ok = [r for r in records if not r["error"] and r["sweep"] == "gap"]
    gaps = sorted({int(r["config"]["gap"]) for r in ok})
    methods = [m for m in METHODS if any(r["config"]["method"] == m for r in ok)]
    if not ok:
        return []
    n_frames = ok[0]["config"]["n_frames"]

    def stats(method, metric, gap=None):
        return mean_se(r["metrics"].get(metric) for r in ok if r["config"]["method"] == method
                       and (gap is None or int(r["config"]["gap"]) == gap))

    def cell(s):
        mean, se, n = s
        return "—" if not n else f"{mean:.4f} ± {se:.4f}"

    lines = [f"# Table 6.1: {title}, {n_frames} frames per trial, node orders shuffled", "",
             "Mean pairwise accuracy ± standard error over the trials (frames spread at the "
             "given gap from a random first frame); last columns: all gaps together, and the "
             "output's cycle consistency and time.", "",
             "| method | " + " | ".join(f"gap {g}" for g in gaps)
             + " | all | consistency | seconds | trials |",
             "|---|" + "---|" * (len(gaps) + 4)]
    for m in methods:
        row = [cell(stats(m, "accuracy", g)) for g in gaps]
        acc_all = stats(m, "accuracy")
        row += [cell(acc_all), f"{stats(m, 'consistency')[0]:.4f}",
                f"{stats(m, 'seconds')[0]:.3g}", str(acc_all[2])]
        lines.append(f"| {m} | " + " | ".join(row) + " |")
    table = out / "table_6_1.md"
    table.write_text("\n".join(lines) + "\n")
    return [table, _plot_table(methods, gaps, stats, out / "table_6_1.png", title, n_frames)]


def _plot_table(methods, gaps, stats, path: Path, title: str, n_frames: int) -> Path:
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(1.2 + 1.1 * len(methods), 3.4))
    width = 0.8 / max(len(gaps), 1)
    x = np.arange(len(methods))
    for k, g in enumerate(gaps):
        s = [stats(m, "accuracy", g) for m in methods]
        ax.bar(x + (k - (len(gaps) - 1) / 2) * width, [v[0] for v in s], width,
               yerr=[v[1] for v in s], capsize=2, label=f"gap {g}")
    ax.set_xticks(x, methods)
    ax.set_ylabel("accuracy")
    lows = [stats(m, "accuracy", g)[0] for m in methods for g in gaps]
    lows = [v for v in lows if np.isfinite(v)]
    ax.set_ylim(max(0.0, min(lows, default=0.0) - 0.05), 1.005)
    ax.grid(axis="y", alpha=0.3)
    ax.legend(fontsize=7, frameon=False, ncol=min(len(gaps), 5))
    ax.set_title(f"Table 6.1: {title}, {n_frames} frames (mean ± s.e.)", fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return path
