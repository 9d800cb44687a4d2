"""Plots of experiment summaries: mean ± standard error per method against the swept variable.

Conventions, the same in every experiment's figure:

* y axes carry a readable label with units (:data:`METRIC_LABELS`; unknown metrics show their
  name with spaces);
* every method keeps one colour, one marker and one line style across panels, so that curves
  lying on top of each other (e.g. all synchronization methods at accuracy 1.0) stay visible;
* numeric sweeps are lines with a shaded band of ± 1 standard error of the mean over trials;
  categorical sweeps (data set names, "no clutter") and one-value sweeps are grouped points with
  error bars, side by side, never joined by lines;
* one legend for the whole figure, outside the panels, and a caption that explains the band and
  gives the number of trials per point (single-trial points have no band);
* on log axes (times, values spanning more than two decades) non-positive means cannot be drawn:
  the legend entry says so instead of silently showing nothing.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ._runner import METRIC_LABELS, metric_label, value_label  # noqa: F401 (re-exported)

__all__ = ["METRIC_LABELS", "metric_label", "plot_experiment", "pyplot", "render_experiment"]

_MARKERS = ("o", "s", "^", "D", "v", "P", "X", "<", ">", "*", "h", "p")
_STYLES = ("-", "--", "-.", ":")


def pyplot():
    """``matplotlib.pyplot`` on the non-interactive Agg backend (experiments write files, on
    machines without a display); imported here, on first use, not at package import."""
    import matplotlib

    matplotlib.use("Agg", force=True)
    import matplotlib.pyplot as plt

    return plt


def _styles(methods: list[str], plt) -> dict[str, dict]:
    cycle = plt.rcParams["axes.prop_cycle"].by_key().get("color", ["C0"])
    return {m: dict(color=cycle[k % len(cycle)], marker=_MARKERS[k % len(_MARKERS)],
                    linestyle=_STYLES[k % len(_STYLES)])
            for k, m in enumerate(methods)}


def _rows(summary, sweep, method, metric):
    return [r for r in summary if r["sweep"] == sweep and r["method"] == method
            and r["metric"] == metric and r["n"] > 0]


def _is_numeric(values) -> bool:
    return len(values) > 1 and all(isinstance(v, (int, float)) and not isinstance(v, bool)
                                   for v in values)


def _log_scale(metric: str, means: np.ndarray) -> bool:
    pos = means[np.isfinite(means) & (means > 0)]
    spans = pos.size > 1 and pos.max() / pos.min() > 100
    return metric in ("seconds", "time") or bool(spans)


def _draw_panel(ax, sw, metric, summary, styles):
    """One (sweep, metric) panel; returns {method: every point drawn?} for the legend."""
    methods = [m for m in sw.methods if _rows(summary, sw.name, m, metric)]
    values = list(sw.values)
    numeric = _is_numeric(values)
    all_means = np.array([r["mean"] for m in methods for r in _rows(summary, sw.name, m, metric)],
                         dtype=float)
    log = _log_scale(metric, all_means) if all_means.size else False
    drawn = {}
    width = 0.8 / max(len(methods), 1)
    for k, method in enumerate(methods):
        rows = _rows(summary, sw.name, method, metric)
        st = styles[method]
        mean = np.array([r["mean"] for r in rows], dtype=float)
        se = np.array([r["se"] if r["n"] > 1 else np.nan for r in rows], dtype=float)
        ok = np.isfinite(mean) & ((mean > 0) if log else True)
        drawn[method] = bool(ok.all())
        if numeric:
            x = np.array([float(r["value"]) for r in rows])
            ax.plot(x[ok], mean[ok], ms=4, lw=1.4, alpha=0.9, **st)
            band = ok & np.isfinite(se)
            lo = mean - se
            if log:
                lo = np.where(lo > 0, lo, mean[ok].min(initial=np.inf) / 10 if ok.any() else 1)
            if band.any():
                ax.fill_between(x[band], lo[band], (mean + se)[band], color=st["color"],
                                alpha=0.15, lw=0)
        else:
            pos = {value_label(v): i for i, v in enumerate(values)}
            x = np.array([pos.get(value_label(r["value"]), -1) for r in rows], dtype=float)
            x = x + (k - (len(methods) - 1) / 2) * width
            err = np.where(np.isfinite(se), se, 0.0)
            ax.errorbar(x[ok], mean[ok], yerr=err[ok], fmt=st["marker"], color=st["color"],
                        ms=5, capsize=2, lw=1.0)
    if numeric and all(isinstance(v, int) for v in values):
        from matplotlib.ticker import MaxNLocator

        ax.xaxis.set_major_locator(MaxNLocator(integer=True))       # no "2.5 frames"
    if not numeric:
        long = any(len(value_label(v)) > 6 for v in values)
        ax.set_xticks(np.arange(len(values)), [value_label(v) for v in values],
                      rotation=30 if long else 0, ha="right" if long else "center")
        ax.set_xlim(-0.6, len(values) - 0.4)
    if log and np.any(all_means[np.isfinite(all_means)] > 0):
        ax.set_yscale("log")
    ax.set_xlabel(sw.xlabel or sw.variable)
    ax.set_ylabel(metric_label(metric), fontsize=8)
    ax.set_title(sw.name, fontsize=10)
    ax.grid(alpha=0.3)
    return drawn


def plot_experiment(experiment, summary: list[dict], path) -> Path:
    """One panel per (sweep, metric), one line (or point group) per method.

    Returns the path of the PNG written. Uses matplotlib's non-interactive Agg backend.
    """
    import matplotlib.pyplot as plt

    fig = render_experiment(experiment, summary)
    path = Path(path)
    fig.savefig(path, dpi=120, bbox_inches="tight")
    plt.close(fig)
    return path


def render_experiment(experiment, summary: list[dict]):
    """The figure of :func:`plot_experiment` (a matplotlib ``Figure``; the caller closes it)."""
    from matplotlib.lines import Line2D

    plt = pyplot()

    nrows = max(1, len(experiment.sweeps))
    ncols = max([len(sw.metrics) for sw in experiment.sweeps] + [1])
    fig, axes = plt.subplots(nrows, ncols, figsize=(4.2 * ncols + 1.8, 3.4 * nrows + 0.6),
                             squeeze=False)
    all_methods = list(dict.fromkeys(m for sw in experiment.sweeps for m in sw.methods))
    styles = _styles(all_methods, plt)
    drawn: dict[str, bool] = {}          # method -> every point of every panel drawn
    for r, sw in enumerate(experiment.sweeps):
        for c in range(ncols):
            if c >= len(sw.metrics):
                axes[r, c].set_visible(False)
                continue
            for m, d in _draw_panel(axes[r, c], sw, sw.metrics[c], summary, styles).items():
                drawn[m] = drawn.get(m, True) and d
    hidden = " (some points not drawn: <= 0 on a log axis)"
    handles = [Line2D([], [], label=m + ("" if drawn[m] else hidden),
                      ms=5, **styles[m]) for m in all_methods if m in drawn]
    if handles:
        fig.legend(handles=handles, loc="center left", bbox_to_anchor=(1.0, 0.5), fontsize=8,
                   frameon=False, title="method", title_fontsize=8)
    counts = sorted({int(r["n"]) for r in summary if r["n"] > 0})
    n_text = (f"{counts[0]}" if len(counts) == 1 else f"{counts[0]}-{counts[-1]}") if counts \
        else "0"
    caption = (f"Mean over {n_text} trial(s) per point; band / error bar: ± 1 standard error of "
               "the mean (none for single trials).")
    fig.text(0.01, 0.005, caption, fontsize=7.5, ha="left", va="bottom", color="0.3")
    title = experiment.name + (f": {experiment.description}" if experiment.description else "")
    fig.suptitle(title, fontsize=11)
    fig.tight_layout(rect=(0, 0.03, 1, 1))
    return fig
