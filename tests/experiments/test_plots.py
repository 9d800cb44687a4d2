"""Every experiment's standard figure, rendered from planted summaries (no trial is run).

Checks the figure conventions of :mod:`transync.experiments._plot`: readable y labels with
units, one legend outside the panels naming every method, categorical sweeps drawn as points
(never joined by lines), single-trial points without a band, non-positive values on a log axis
named in the legend, and a caption explaining the band.
"""

import importlib

import matplotlib
import numpy as np
import pytest

from transync.experiments import REGISTRY, Experiment, Sweep
from transync.experiments._plot import metric_label, render_experiment
from transync.experiments._runner import _write_summary

matplotlib.use("Agg", force=True)
import matplotlib.pyplot as plt  # noqa: E402

# experiments whose quick build needs no data folder
_NO_DATA = [name for name in REGISTRY if name not in ("cmu", "kernels")]


def _planted(experiment, rng, *, single=None, zero_time=None):
    rows = []
    for sw in experiment.sweeps:
        for value in sw.values:
            for method in sw.methods:
                for metric in sw.metrics:
                    mean = float(rng.uniform(0.1, 1.0))
                    if metric == "seconds":
                        mean = 0.0 if method == zero_time else float(rng.uniform(0.01, 10))
                    n = 1 if method == single else 5
                    rows.append(dict(sweep=sw.name, variable=sw.variable, value=value,
                                     method=method, metric=metric, mean=mean,
                                     se=0.0 if n == 1 else 0.02, n=n, failed=0))
    return rows


def _categorical(values) -> bool:
    return not (len(values) > 1 and all(isinstance(v, (int, float)) and not isinstance(v, bool)
                                        for v in values))


@pytest.mark.parametrize("name", _NO_DATA)
def test_every_experiment_figure_follows_the_conventions(name, rng):
    exp = importlib.import_module(REGISTRY[name]).build(quick=True)
    methods = list(dict.fromkeys(m for sw in exp.sweeps for m in sw.methods))
    fig = render_experiment(exp, _planted(exp, rng))
    try:
        axes = [ax for ax in fig.axes if ax.get_visible()]
        panels = [(sw, metric) for sw in exp.sweeps for metric in sw.metrics]
        assert len(axes) == len(panels)
        for ax, (sw, metric) in zip(axes, panels):
            assert ax.get_ylabel() == metric_label(metric)
            assert ax.get_xlabel() == (sw.xlabel or sw.variable)
            assert ax.get_legend() is None                      # one legend, outside
            if _categorical(list(sw.values)):
                assert all(line.get_linestyle() == "None" for line in ax.lines), sw.name
        (legend,) = fig.legends
        assert [t.get_text() for t in legend.get_texts()] == methods
        assert any("standard error" in t.get_text() for t in fig.texts)
    finally:
        plt.close(fig)


def _toy(values):
    sw = Sweep(name="toy", variable="x", values=values, methods=["a", "b", "c"],
               metrics=("accuracy", "seconds"))
    return Experiment(name="toy", sweeps=[sw], trial=lambda config, rng: {})


def test_single_trials_have_no_band_and_zero_times_are_named(rng):
    exp = _toy([1, 2, 4])
    fig = render_experiment(exp, _planted(exp, rng, single="b", zero_time="c"))
    try:
        acc, sec = [ax for ax in fig.axes if ax.get_visible()]
        # one band per method with several trials (a, c), none for the single-trial method b
        assert len(acc.collections) == 2
        assert sec.get_yscale() == "log"
        labels = [t.get_text() for t in fig.legends[0].get_texts()]
        assert labels[:2] == ["a", "b"] and "not drawn" in labels[2]
        # overlapping curves stay distinguishable: distinct markers and line styles
        styles = {(ln.get_marker(), ln.get_linestyle()) for ln in acc.lines}
        assert len(styles) == 3
    finally:
        plt.close(fig)


def test_one_value_and_categorical_sweeps_are_grouped_points(rng):
    for values in ([2], ["no clutter", "clutter"]):
        exp = _toy(values)
        fig = render_experiment(exp, _planted(exp, rng))
        try:
            ax = [a for a in fig.axes if a.get_visible()][0]
            assert all(line.get_linestyle() == "None" for line in ax.lines)
            assert [t.get_text() for t in ax.get_xticklabels()] == [str(v) for v in values]
            lo, hi = ax.get_xlim()
            assert lo < 0 and hi > len(values) - 1                 # not a 1.9-2.1 axis
            xs = np.concatenate([line.get_xdata() for line in ax.lines])
            assert len(np.unique(np.round(xs, 6))) == 3 * len(values)   # methods side by side
        finally:
            plt.close(fig)


def test_summary_table_says_single_trial_instead_of_zero_error(tmp_path, rng):
    exp = _toy([1, 2])
    _write_summary(_planted(exp, rng, single="b"), tmp_path)
    text = (tmp_path / "summary.md").read_text()
    assert "(1 trial)" in text and "± 0 " not in text and "± 0|" not in text
    assert "time per trial (s)" in text and "standard error" in text
