"""Reweighted random walks for graph matching (Cho, Lee & Lee, ECCV 2010).

The default (``variant="original"``) follows the authors' MATLAB code (``RRWM.m`` v1.22):
conflicting entries of ``K`` are dropped, ``Mo = K / max column sum``, and each iteration mixes a
random-walk step (weight ``c = 0.2``) with a reweighted jump (weight ``1 - c = 0.8``) towards the
Sinkhorn-normalised, exponentially amplified current scores; its inner Sinkhorn is warm-started
from one iteration to the next unless ``warm_start=False`` (the authors' loop exactly, about 10x
slower, the same assignments on 290 of 296 problems measured). ``variant="pygmtools"`` reproduces
``pygmtools.rrwm`` instead (same iterates, same assignments), so results can be compared with, or
swapped for, that library's.

Examples
--------
>>> import numpy as np
>>> from transync.graphs import Graph
>>> from transync.matching import gaussian_edge_affinity, rrwm
>>> rng = np.random.default_rng(1)
>>> g1 = Graph.from_points(rng.random((10, 2)), edges="full")
>>> perm = rng.permutation(10)
>>> res = rrwm(gaussian_edge_affinity(g1, g1.permute(perm)))
>>> bool(np.all(perm[res.assignment] == np.arange(10))), res.converged
(True, True)
"""

from __future__ import annotations

import numpy as np

from .._validation import (
    MAX_ITER,
    check_affinity_scale,
    check_choice,
    check_int,
    check_positive,
    check_probability,
)
from ..permutations import solve_lap
from ._affinity import as_affinity
from ._result import MatchingResult
from ._sinkhorn import sinkhorn_normalize
from ._stepwise import _BaseStepper, _run

__all__ = ["RRWMStepper", "rrwm"]

VARIANTS = ("original", "pygmtools")
#: largest ``amplification`` of ``variant="original"``, whose Sinkhorn runs on ``exp(amp x)``
#: with ``max x = 1`` in the scaling domain (``exp`` overflows float64 beyond ~709)
MAX_AMPLIFICATION = 500.0
# per variant; the original values are RRWM.m's, the pygmtools values pygmtools 0.6's defaults
# (alpha = 1 - c = 0.2, beta = 30, max_iter = 50, sk_iter = 20 half-sweeps, its threshold 1e-5)
_DEFAULTS = {
    "original": {"c": 0.2, "amplification": 30.0, "max_iter": 300, "tol": 1e-25,
                 "sinkhorn_tol": 1e-3, "sinkhorn_max_iter": 1000},
    "pygmtools": {"c": 0.8, "amplification": 30.0, "max_iter": 50, "tol": 1e-5,
                  "sinkhorn_tol": 0.0, "sinkhorn_max_iter": 20},
}
# variant="original" with its Sinkhorn warm-started (the default): the sweeps carry over from one
# iteration to the next, so each call is capped lower and the loop also waits for the Sinkhorn
# tolerance; stopping at a squared change of 1e-12 instead of RRWM.m's 1e-25 (a bit-for-bit fixed
# point, which a warm start never reaches), or once the rounding is stable (RRWMStepper's
# stable_every / stable_checks). Measured on 296 problems (complete and Delaunay graphs,
# n = 12-60, with outliers, CMU House pairs): identical assignments on 290, 10x less time; see
# the rrwm docstring.
_WARM_DEFAULTS = {"tol": 1e-12, "sinkhorn_max_iter": 100}


def _sinkhorn_half_sweeps(S: np.ndarray, half_sweeps: int) -> np.ndarray:
    """pygmtools' Sinkhorn of ``exp(S)``: ``half_sweeps`` normalisations, smaller side first.

    No slack: with ``n1 != n2`` the sides alternate between summing to one, exactly as
    ``pygmtools.sinkhorn`` does without ``dummy_row``. pygmtools works in the log domain; while
    the score range ``max S - min S`` stays below 600 the kernel ``exp(S - max S)`` cannot
    underflow and the same normalisations are done in the scaling domain (about 10x cheaper).
    """
    top = S.max()
    if top - S.min() < 600.0:
        return sinkhorn_normalize(np.exp(S - top), domain="scaling", slack="none",
                                  half_sweeps=half_sweeps).X
    return sinkhorn_normalize(S, domain="log", slack="none", half_sweeps=half_sweeps).X


class RRWMStepper(_BaseStepper):
    """Step-wise RRWM: one random-walk-with-reweighted-jump iteration per :meth:`step`.

    ``RRWMStepper(K, variant=...)`` returns the stepper of that variant, a subclass:

    ``variant="original"`` (the authors' code). State: the walk scores ``x`` (sum 1), the jump
    distribution ``y`` and, with ``warm_start``, the Sinkhorn scaling carried to the next step
    and the last roundings of the stability stop. The public :attr:`iterate` is ``y`` before its
    sum-normalisation, i.e. the Sinkhorn output -- a doubly-stochastic matrix (``n1 == n2``)
    or, with the slack convention, one whose smaller side is stochastic and larger side
    sub-stochastic. :meth:`set_iterate` replaces ``y`` (``x`` is kept). The rounding uses the
    walk scores ``x``, as the original code does.

    ``variant="pygmtools"``. State: the mixture ``v = normalise(alpha S + (1 - alpha) w)`` of the
    normalised walk ``w = Mo v`` and the (truncated) Sinkhorn output ``S``; :attr:`iterate` is
    ``S``, :meth:`set_iterate` replaces ``S`` and re-forms ``v``; the rounding uses ``v``.

    Parameters are those of :func:`rrwm`.

    Parameters
    ----------
    affinity : Affinity or array_like/sparse of shape (n1 n2, n1 n2)
        The affinity ``K``.
    variant : {"original", "pygmtools"}, optional
        Which published implementation to follow (default ``"original"``), as in :func:`rrwm`.
    **kwargs
        ``n1``, ``n2`` and the options of :func:`rrwm` (``c``, ``amplification``, ``max_iter``,
        ``tol``, ``sinkhorn_tol``, ``sinkhorn_max_iter``, ``warm_start``), by keyword only.

    Raises
    ------
    ValueError, TypeError
        Invalid ``affinity``, ``variant`` or options (as :func:`rrwm`).

    Examples
    --------
    >>> import numpy as np
    >>> K = np.ones((4, 4)) + 3 * np.eye(4)              # n1 = n2 = 2
    >>> K[1, 2] = K[2, 1] = 0.0
    >>> s = RRWMStepper(K, n1=2, n2=2)
    >>> while not s.step():
    ...     pass
    >>> s.result().assignment
    array([0, 1])
    """

    method = "rrwm"
    variant = ""
    #: The warm-started original loop also stops once the Hungarian rounding of the walk scores
    #: is the same at ``stable_checks`` checks ``stable_every`` iterations apart.
    stable_every = 10
    stable_checks = 3

    def __new__(cls, affinity=None, *args, variant: str | None = None, **kwargs):
        if cls is RRWMStepper:
            cls = _VARIANT_CLASSES[check_choice("original" if variant is None else variant,
                                                "variant", VARIANTS)]
        elif variant is not None and variant != cls.variant:   # (None: unpickling, copies)
            raise ValueError(f"{cls.__name__} implements variant={cls.variant!r}, got "
                             f"variant={variant!r}")
        return super().__new__(cls)

    def __init__(self, affinity, *, n1: int | None = None, n2: int | None = None,
                 variant: str = "original", c: float | None = None,
                 amplification: float | None = None, max_iter: int | None = None,
                 tol: float | None = None, sinkhorn_tol: float | None = None,
                 sinkhorn_max_iter: int | None = None, warm_start: bool | None = None):
        if warm_start is not None and not isinstance(warm_start, (bool, np.bool_)):
            raise TypeError(f"`warm_start` must be a bool or None, got "
                            f"{type(warm_start).__name__} {warm_start!r}")
        self.warm_start = self._resolve_warm_start(None if warm_start is None
                                                   else bool(warm_start))
        d = {**_DEFAULTS[self.variant], **(_WARM_DEFAULTS if self.warm_start else {})}
        pick = lambda value, key: d[key] if value is None else value  # noqa: E731
        aff = as_affinity(affinity, n1=n1, n2=n2)
        super().__init__(aff, max_iter=check_int(pick(max_iter, "max_iter"), "max_iter",
                                                 minimum=1, maximum=MAX_ITER))
        self.c = check_probability(pick(c, "c"), "c")
        self.amplification = check_positive(pick(amplification, "amplification"),
                                            "amplification")
        if self.variant == "original" and self.amplification > MAX_AMPLIFICATION:
            raise ValueError(f"`amplification` must be <= {MAX_AMPLIFICATION:g} with "
                             f"variant='original' (its Sinkhorn scales exp(amplification), "
                             f"which overflows float64 beyond ~709), got {self.amplification!r}")
        self.tol = check_positive(pick(tol, "tol"), "tol")
        self.sinkhorn_max_iter = check_int(pick(sinkhorn_max_iter, "sinkhorn_max_iter"),
                                           "sinkhorn_max_iter", minimum=1, maximum=MAX_ITER)
        self.sinkhorn_sweeps = 0
        self.stop = None            # why the loop stopped: "tolerance", "stable rounding"
        # the Sinkhorn output before any step: uniform, feasible with and without slack
        self._X = np.full((self.n1, self.n2), 1.0 / max(self.n1, self.n2))
        self._setup(aff, sinkhorn_tol)

    def _resolve_warm_start(self, warm_start) -> bool:  # pragma: no cover - overridden
        raise NotImplementedError

    def _setup(self, aff, sinkhorn_tol) -> None:  # pragma: no cover - overridden
        raise NotImplementedError

    def set_iterate(self, X) -> None:
        X = self._check_iterate(X)
        total = X.sum()
        if total <= 0:
            raise ValueError("`X` must have a positive sum")
        self._X = X
        self._set_jump(X, total)
        self.converged, self.stop = False, None

    def step(self) -> bool:
        if self.done:
            return True
        self._step()
        self.n_iter += 1
        return self.done

    def _info(self) -> dict:
        return {"scores": self._rounding_scores().copy(), "max_degree": self.max_degree,
                "sinkhorn_sweeps": self.sinkhorn_sweeps, "variant": self.variant,
                "warm_start": self.warm_start, "stop": self.stop}


class _OriginalRRWMStepper(RRWMStepper):
    """RRWM as in the authors' MATLAB code (``RRWM.m`` v1.22); see :class:`RRWMStepper`."""

    variant = "original"

    def _resolve_warm_start(self, warm_start) -> bool:
        return True if warm_start is None else warm_start

    def _setup(self, aff, sinkhorn_tol) -> None:
        self.sinkhorn_tol = check_positive(
            _DEFAULTS["original"]["sinkhorn_tol"] if sinkhorn_tol is None else sinkhorn_tol,
            "sinkhorn_tol")
        self._walk = aff.drop_conflicts()
        self.max_degree = self._walk.max_column_sum()
        check_affinity_scale(self.max_degree)
        self._scale = 1.0 / self.max_degree if self.max_degree > 0 else 0.0
        size = self.n1 * self.n2
        self._x = np.full((self.n1, self.n2), 1.0 / size)       # prev_score
        self._x2 = self._x.copy()                                 # prev_score2
        self._y = np.full((self.n1, self.n2), 1.0 / size)         # prev_assign (sum 1)
        self._scaling = None                                      # Sinkhorn warm start
        self._roundings = []                                      # stability checks (warm)

    def _set_jump(self, X, total) -> None:
        self._y = X / total
        self._roundings = []

    def _step(self) -> None:
        c = self.c
        x = self._walk.matvec(c * self._x + (1.0 - c) * self._y) * self._scale
        s = x.sum()
        if s > 0:
            x /= s
        xmax = x.max()
        amp = self.amplification / xmax if xmax > 0 else 0.0
        out = sinkhorn_normalize(np.exp(amp * x), domain="scaling", slack="mass",
                                 tol=self.sinkhorn_tol, max_iter=self.sinkhorn_max_iter,
                                 check_every=4, warm_start=self._scaling)
        if self.warm_start:
            self._scaling = out.col_scaling
        # sweeps begun: a converged run stops at the test that opens the next sweep
        self.sinkhorn_sweeps += out.n_sweeps + int(out.converged)
        X = self._X = out.X
        sy = X.sum()
        y = X / sy if sy > 0 else X
        diff = min(float(np.sum((x - self._x) ** 2)), float(np.sum((x - self._x2) ** 2)))
        self._x2, self._x, self._y = self._x, x, y
        # warm: the Sinkhorn goes on converging across steps, so its tolerance must hold too
        if diff < self.tol and (out.converged or not self.warm_start):
            self.converged, self.stop = True, "tolerance"
        elif self.warm_start and (self.n_iter + 1) % self.stable_every == 0:
            a = solve_lap(x)
            self._roundings = (self._roundings + [a])[-self.stable_checks:]
            if len(self._roundings) == self.stable_checks and all(
                    np.array_equal(a, b) for b in self._roundings):
                self.converged, self.stop = True, "stable rounding"

    def _rounding_scores(self) -> np.ndarray:
        return self._x


class _PygmtoolsRRWMStepper(RRWMStepper):
    """RRWM as ``pygmtools.rrwm`` (0.6, numpy backend); see :class:`RRWMStepper`."""

    variant = "pygmtools"

    def _resolve_warm_start(self, warm_start) -> bool:
        if warm_start:
            raise ValueError("`warm_start` is not used by variant='pygmtools' (its Sinkhorn starts "
                             f"afresh every iteration, as pygmtools'), got {warm_start!r}")
        return False

    def _setup(self, aff, sinkhorn_tol) -> None:
        if sinkhorn_tol is not None:
            raise ValueError("`sinkhorn_tol` is not used by variant='pygmtools' (its Sinkhorn "
                             f"runs `sinkhorn_max_iter` half-sweeps), got {sinkhorn_tol!r}")
        self.sinkhorn_tol = None
        # pygmtools: K / (max row sum + 1e-5 min row sum), conflicts kept
        self._walk = aff
        rows = aff.matvec(np.ones((self.n1, self.n2)))
        self.max_degree = float(rows.max()) if rows.size else 0.0
        check_affinity_scale(self.max_degree)
        denom = self.max_degree + float(rows.min(initial=0.0)) * 1e-5
        self._scale = 1.0 / denom if denom > 0 else 0.0
        self._v = np.full((self.n1, self.n2), 1.0 / (self.n1 * self.n2))
        self._w = self._v.copy()

    def _set_jump(self, X, total) -> None:
        v = (1.0 - self.c) * X + self.c * self._w
        self._v = v / v.sum()

    def _step(self) -> None:
        # pygmtools 0.6 numpy_backend.rrwm, one loop iteration (alpha = 1 - c)
        alpha = 1.0 - self.c
        raw = self._walk.matvec(self._v) * self._scale
        s = np.abs(raw).sum()
        w = raw / s if s > 0 else raw
        wmax = w.max()
        scores = self.amplification * w / wmax if wmax > 0 else np.zeros_like(w)
        S = _sinkhorn_half_sweeps(scores, self.sinkhorn_max_iter)
        self.sinkhorn_sweeps += self.sinkhorn_max_iter
        v = alpha * S + (1.0 - alpha) * w
        v /= np.abs(v).sum()
        # pygmtools' own test compares v with the un-normalised walk and practically never fires;
        # the loop also counts as converged once the mixture itself has settled.
        settled = min(np.linalg.norm(v - raw), np.linalg.norm(v - self._v)) < self.tol
        self._X, self._w, self._v = S, w, v
        if settled:
            self.converged, self.stop = True, "tolerance"

    def _rounding_scores(self) -> np.ndarray:
        return self._v


def rrwm(K, *, n1: int | None = None, n2: int | None = None, variant: str = "original",
         c: float | None = None, amplification: float | None = None,
         max_iter: int | None = None, tol: float | None = None,
         sinkhorn_tol: float | None = None, sinkhorn_max_iter: int | None = None,
         warm_start: bool | None = None) -> MatchingResult:
    """Reweighted random walks (RRWM): by default the original authors' model, warm-started.

    ``variant="original"``: with ``Mo`` the conflict-free ``K`` divided by its largest column
    sum, iterate

    .. math:: x \\leftarrow \\frac{M_o (c\\,x + (1 - c)\\,y)}{\\mathbf 1^\\top(\\cdot)}, \\qquad
              y \\leftarrow \\frac{\\mathrm{Sinkhorn}(\\exp(\\beta x / \\max x))}{\\mathbf 1^\\top(\\cdot)}

    until ``min(||x - x_prev||^2, ||x - x_prev2||^2) < tol``, and round ``x`` with the Hungarian
    algorithm. Sinkhorn runs to ``sinkhorn_tol`` and uses a slack row/column of mass
    ``|n2 - n1|`` when the sizes differ.

    By default (``warm_start=True``) each Sinkhorn starts from the previous iteration's scaling
    instead of ones, at most 100 sweeps a call, and the loop stops once the squared change is
    below 1e-12 *and* the last Sinkhorn met its tolerance, or once the Hungarian rounding of
    ``x`` is the same at three checks ten iterations apart (hard problems whose scores keep
    drifting; ``info["stop"]`` says which). The authors' code restarts Sinkhorn from ones (up
    to 1000 sweeps: on a peaked ``exp(30 x / max x)`` it often needs hundreds) and stops at
    1e-25 only, i.e. at a bit-for-bit fixed point; ``warm_start=False`` runs exactly that loop.
    Measured on 296 problems (complete graphs n = 20, 50 at sigma2 0.02 / 0.05 / 0.15 with and
    without a third outliers; 12 points against 16 or 20 with slack; Delaunay graphs n = 30,
    60; CMU House pairs; deformation 0-0.04): the same assignment on 290, the other 6 as
    accurate or more (1.4 points higher on average), in a tenth of the time (1.9 s against
    19.6 s in all; pygmtools' variant 1.35 s).

    ``variant="pygmtools"``: the loop of ``pygmtools.rrwm`` (0.6): ``K`` (conflicts kept) divided
    by its largest row sum; ``w = normalise(K v)``, ``S`` = ``sinkhorn_max_iter`` log-domain
    half-sweeps of ``beta w / max w`` (not run to convergence, no slack), ``v = normalise((1 - c) S
    + c w)``; at most 50 iterations; round ``v``. Because ``S`` sums to ``min(n1, n2)`` and ``w``
    to one, the jump dominates the mixture. pygmtools' own stopping test compares ``v`` with the
    un-normalised walk and practically never fires; here the loop also stops once ``v`` moves
    by less than ``tol``. Run for 50 iterations (``tol`` tiny) the iterates equal pygmtools' to
    1e-10; with the default stop the assignments were identical on every problem compared
    (the tests, and 50 problems with n <= 30 with and without outliers).

    The two differ with outliers: measured on fully connected point-set graphs with a third of
    the nodes outliers, the truncated Sinkhorn and the rounding of the mixture make
    ``"pygmtools"`` 2-7 points more accurate there (equal without outliers) -- see
    ``benchmarks/README.md``.

    Parameters
    ----------
    K : Affinity or array_like/sparse of shape (n1 n2, n1 n2)
        Affinity (pygmtools layout when a matrix).
    n1, n2 : int, optional
        Graph sizes; required when ``K`` is a matrix.
    variant : {"original", "pygmtools"}, default="original"
        Which published implementation to follow; ``None`` parameters take its defaults.
    c : float, optional
        Weight of the random walk; ``1 - c`` weights the reweighted jump (pygmtools' ``alpha``
        is ``1 - c``). Default 0.2 (original), 0.8 (pygmtools).
    amplification : float, optional
        ``beta``: the largest score is amplified to ``exp(beta)`` before Sinkhorn. Default 30;
        at most 500 with ``variant="original"`` (whose Sinkhorn scales
        ``exp(beta)`` itself; ``"pygmtools"`` shifts to the log domain from 600).
    max_iter : int, optional
        Maximum number of iterations. Default 300 (original), 50 (pygmtools).
    tol : float, optional
        Convergence threshold: on the squared change of the scores (original: default 1e-12,
        1e-25 with ``warm_start=False``), on the change of the mixture ``v`` (pygmtools, default
        1e-5).
    sinkhorn_tol : float, optional
        Row-sum tolerance of the inner Sinkhorn normalisation (original only; default 1e-3).
    sinkhorn_max_iter : int, optional
        Original: maximum Sinkhorn sweeps per iteration (default 100; 1000 with
        ``warm_start=False``). pygmtools: the exact number of half-sweeps (default 20).
    warm_start : bool, optional
        Original only: start each Sinkhorn from the previous one's scaling, with the stops
        described above (default ``True``);
        ``False`` reproduces ``RRWM.m`` (with its defaults ``tol=1e-25``,
        ``sinkhorn_max_iter=1000``). pygmtools' variant refuses ``True``.

    Returns
    -------
    MatchingResult
        ``soft`` is the last Sinkhorn output; ``info["scores"]`` the matrix that was rounded;
        ``info["stop"]`` why the loop stopped (``"tolerance"``, ``"stable rounding"``, or
        ``None`` at ``max_iter``).

    Raises
    ------
    ValueError, TypeError
        Invalid ``K`` or parameters.

    Warns
    -----
    ConvergenceWarning
        When ``max_iter`` is reached (``converged=False``).

    References
    ----------
    M. Cho, J. Lee and K. M. Lee, "Reweighted random walks for graph matching", ECCV 2010.

    Examples
    --------
    >>> import numpy as np
    >>> K = np.ones((4, 4)) + 3 * np.eye(4)
    >>> K[1, 2] = K[2, 1] = 0.0
    >>> rrwm(K, n1=2, n2=2).assignment
    array([0, 1])
    >>> rrwm(K, n1=2, n2=2, variant="pygmtools").assignment
    array([0, 1])
    >>> rrwm(K, n1=2, n2=2, warm_start=False).assignment     # RRWM.m's loop exactly
    array([0, 1])
    """
    return _run(RRWMStepper(K, n1=n1, n2=n2, variant=variant, c=c, amplification=amplification,
                            max_iter=max_iter, tol=tol, sinkhorn_tol=sinkhorn_tol,
                            sinkhorn_max_iter=sinkhorn_max_iter, warm_start=warm_start))


# variant name -> stepper class (explicit: subclasses elsewhere never replace a variant)
_VARIANT_CLASSES: dict[str, type] = {
    "original": _OriginalRRWMStepper,
    "pygmtools": _PygmtoolsRRWMStepper,
}
