"""Plots of experiment summaries: mean ± standard error per method against the swept variable."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ._runner import value_label

__all__ = ["plot_experiment"]


def plot_experiment(experiment, summary: list[dict], path) -> Path:
    """One panel per (sweep, metric), one line per method with a standard-error band.

    Returns the path of the PNG written. Uses matplotlib's non-interactive Agg backend.
    """
    import matplotlib

    matplotlib.use("Agg", force=True)
    import matplotlib.pyplot as plt

    # one row per sweep, one column per metric
    nrows = max(1, len(experiment.sweeps))
    ncols = max([len(sw.metrics) for sw in experiment.sweeps] + [1])
    fig, axes = plt.subplots(nrows, ncols, figsize=(4.2 * ncols, 3.3 * nrows), squeeze=False)
    panels = []
    for r, sw in enumerate(experiment.sweeps):
        for c in range(ncols):
            if c < len(sw.metrics):
                panels.append((axes[r, c], sw, sw.metrics[c]))
            else:
                axes[r, c].set_visible(False)
    # one colour per method across all panels (sweeps may compare different subsets)
    all_methods = list(dict.fromkeys(m for sw in experiment.sweeps for m in sw.methods))
    cycle = plt.rcParams["axes.prop_cycle"].by_key().get("color", ["C0"])
    colors = {m: cycle[k % len(cycle)] for k, m in enumerate(all_methods)}
    for ax, sw, metric in panels:
        for method in sw.methods:
            rows = [r for r in summary if r["sweep"] == sw.name and r["method"] == method
                    and r["metric"] == metric and r["n"] > 0]
            if not rows:
                continue
            xs = [r["value"] for r in rows]
            numeric = all(isinstance(x, (int, float)) for x in xs)
            x = np.asarray(xs, dtype=float) if numeric else np.arange(len(xs))
            mean = np.array([r["mean"] for r in rows])
            se = np.array([r["se"] for r in rows])
            line, = ax.plot(x, mean, marker="o", ms=3.5, lw=1.5, label=method,
                            color=colors[method])
            ax.fill_between(x, mean - se, mean + se, color=line.get_color(), alpha=0.2, lw=0)
            if not numeric:
                ax.set_xticks(x, [value_label(v) for v in xs], rotation=30)
        ax.set_xlabel(sw.xlabel or sw.variable)
        ax.set_ylabel(metric)
        ax.set_title(sw.name, fontsize=10)
        # log scale for times and for values spanning more than two decades (e.g. errors
        # of a failing baseline next to sub-pixel ones)
        ys = np.concatenate([ln.get_ydata() for ln in ax.lines]) if ax.lines else np.ones(1)
        ys = ys[np.isfinite(ys)]
        spans = ys.size and ys.min() > 0 and ys.max() / ys.min() > 100
        if ax.lines and (metric in ("seconds", "time") or spans):
            ax.set_yscale("log")
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7, frameon=False)
    title = experiment.name + (f": {experiment.description}" if experiment.description else "")
    fig.suptitle(title, fontsize=11)
    fig.tight_layout()
    path = Path(path)
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return path
