"""``match_graphs``: one front door for pairwise graph matching.

Examples
--------
>>> import numpy as np
>>> from transync.graphs import Graph
>>> from transync.matching import match_graphs
>>> rng = np.random.default_rng(0)
>>> g1 = Graph.from_points(rng.random((12, 2)), edges="full")
>>> perm = rng.permutation(12)
>>> res = match_graphs(g1, g1.permute(perm), method="rrwm")
>>> bool(np.all(perm[res.assignment] == np.arange(12)))
True
"""

from __future__ import annotations

import difflib
import inspect

from ..graphs import Graph
from .._validation import (check_affinity_magnitude, check_affinity_scale, check_array,
                           check_choice, check_positive)
from ..exceptions import DegenerateInputError
from ._affinity import (
    DEFAULT_SIGMA2,
    as_affinity,
    gaussian_edge_affinity,
    gaussian_node_affinity,
)
from ._ga import ga
from ._ipfp import ipfp
from ._linear import hungarian, sinkhorn
from ._pf import pf
from ._result import MatchingResult
from ._rrwm import rrwm
from ._sm import sm

__all__ = ["METHODS", "match_graphs", "solver_options"]

METHODS = {
    "hungarian": hungarian,
    "sinkhorn": sinkhorn,
    "sm": sm,
    "rrwm": rrwm,
    "ipfp": ipfp,
    "ga": ga,
    "pf": pf,
}
_LINEAR = ("hungarian", "sinkhorn")


def solver_options(method: str) -> tuple[str, ...]:
    """Names of the options that ``match_graphs(..., method=method, **options)`` passes on.

    Read from the solver's signature: its keyword-only parameters except ``n1`` and ``n2``, which
    the front door sets from the graphs.

    Parameters
    ----------
    method : str
        One of :data:`METHODS`.

    Returns
    -------
    tuple of str
        The option names, in the solver's order.

    Raises
    ------
    ValueError
        Unknown ``method``.

    Examples
    --------
    >>> solver_options("sm")
    ('max_iter', 'tol')
    """
    check_choice(method, "method", tuple(METHODS))
    params = inspect.signature(METHODS[method]).parameters.values()
    return tuple(p.name for p in params
                 if p.kind is inspect.Parameter.KEYWORD_ONLY and p.name not in ("n1", "n2"))


def _check_options(method: str, options: dict) -> None:
    accepted = solver_options(method)
    unknown = [name for name in options if name not in accepted]
    if unknown:
        hints = [difflib.get_close_matches(name, accepted, n=1) for name in unknown]
        hint = "; ".join(f"did you mean {h[0]!r} for {u!r}?" for u, h in zip(unknown, hints) if h)
        raise TypeError(f"match_graphs(method={method!r}) got unknown solver option(s) "
                        f"{', '.join(repr(u) for u in unknown)}; {method} accepts "
                        f"{', '.join(accepted) or 'no options'}" + (f" ({hint})" if hint else ""))


def match_graphs(g1: Graph, g2: Graph, *, method: str = "rrwm", affinity=None,
                 sigma2: float = DEFAULT_SIGMA2, node_affinity=None, **options) -> MatchingResult:
    """Match two graphs.

    Parameters
    ----------
    g1, g2 : Graph
        The graphs, with ``n1`` and ``n2`` nodes.
    method : {"rrwm", "sm", "ipfp", "ga", "pf", "hungarian", "sinkhorn"}, default="rrwm"
        Solver. The quadratic ones (``sm``, ``rrwm``, ``ipfp``, ``ga``, ``pf``) maximize
        ``vec(X)^T K vec(X)``; the linear ones (``hungarian``, ``sinkhorn``) maximize the unary
        score only (``node_affinity``, or the diagonal of ``affinity``).
    affinity : Affinity or array_like/sparse of shape (n1 n2, n1 n2), optional
        The affinity ``K`` (a matrix uses pygmtools' layout: candidate ``(i, a)`` has index
        ``a n1 + i``). Default: :func:`gaussian_edge_affinity` of the two graphs with ``sigma2``
        and ``node_affinity`` (never materialized).
    sigma2 : float, default=0.15
        Kernel width of the default affinity.
    node_affinity : array_like of shape (n1, n2), optional
        Unary term. Default for the linear methods when ``affinity`` is not given:
        :func:`gaussian_node_affinity` on the node features.
    **options
        Passed to the solver (e.g. ``max_iter``, ``tol``); see each solver's parameters, or
        :func:`solver_options`. Unknown names raise ``TypeError`` before anything is computed.

    Returns
    -------
    MatchingResult
        The assignment (``assignment[u] = v``, ``-1`` unmatched), the solver's soft matrix when
        it has one, the objective ``x^T K x``, iterations and convergence.

    Raises
    ------
    ValueError, TypeError
        Unknown method or solver option, graphs that are not :class:`~transync.graphs.Graph`
        objects, an ``affinity`` whose size does not match ``n1 n2``, or a linear method without a
        unary term.
    DegenerateInputError
        The default Gaussian affinity underflows (``sigma2`` far below the squared scale of the
        points); the message suggests a ``sigma2``.

    Examples
    --------
    >>> from transync.datasets import make_point_matching_problem
    >>> p = make_point_matching_problem(n_inliers=10, rng=0)       # rotated, shuffled copy
    >>> res = match_graphs(p.g1, p.g2, method="rrwm")
    >>> bool((res.assignment == p.truth).all()), res.converged
    (True, True)
    """
    check_choice(method, "method", tuple(METHODS))
    _check_options(method, options)
    sigma2 = check_positive(sigma2, "sigma2")
    if not isinstance(g1, Graph) or not isinstance(g2, Graph):
        raise TypeError(f"`g1` and `g2` must be Graph objects, got {type(g1).__name__} and "
                        f"{type(g2).__name__}")
    n1, n2 = g1.n_nodes, g2.n_nodes
    solver = METHODS[method]
    if affinity is not None:
        aff = as_affinity(affinity, n1=n1, n2=n2, name="affinity")
        if method in _LINEAR and node_affinity is None:
            if not aff.diag().any():    # an edge-only affinity: nothing for them to rank
                raise ValueError(f"method={method!r} scores nodes by the diagonal of `affinity` "
                                 "(its unary term), and this one's diagonal is all zero (an "
                                 "edge-only affinity): pass `node_affinity`, or use a "
                                 "quadratic method")
            return solver(aff, **options)
        if method not in _LINEAR:        # named as given here (the solvers call it `K`)
            check_affinity_scale(aff.max_column_sum(), "affinity")
    else:
        aff = None
    if method in _LINEAR:
        if node_affinity is None:
            if g1.node_features is None or g2.node_features is None:
                raise ValueError(f"method={method!r} needs a unary term: pass `node_affinity` "
                                 "(shape (n1, n2)), an `affinity` with a diagonal, or graphs with "
                                 "`node_features`")
            try:
                node_affinity = gaussian_node_affinity(g1, g2)
            except DegenerateInputError as exc:   # `sigma2` is the edge bandwidth: not here
                raise DegenerateInputError(
                    f"method={method!r} scores nodes with gaussian_node_affinity(g1, g2) "
                    f"(bandwidth 1.0), which underflows on these node features: pass "
                    f"`node_affinity=gaussian_node_affinity(g1, g2, sigma2=...)` with a larger "
                    f"bandwidth ({exc})") from None
        S = check_array(node_affinity, "node_affinity", ndim=2)
        if S.shape != (n1, n2):
            raise ValueError(f"`node_affinity` must have shape ({n1}, {n2}), got {S.shape}")
        check_affinity_magnitude(abs(S).max(), S.size, "node_affinity")
        return solver(S, **options)
    if aff is None:
        aff = gaussian_edge_affinity(g1, g2, sigma2=sigma2, node_affinity=node_affinity)
    elif node_affinity is not None:
        raise ValueError("pass the unary term inside `affinity` (its diagonal), not as "
                         "`node_affinity`, when `affinity` is given")
    return solver(aff, **options)
