"""CAO, CAO-C, CAO-UC and CAO-PC: composition-based affinity optimization (Yan et al., TPAMI 2016).

Every pairwise map ``X_ij`` is replaced, sweep after sweep, by the best of its compositions
``X_ik X_kj`` through every graph ``k`` (``k = i`` or ``k = j`` gives ``X_ij`` itself), the
fitness mixing the normalized affinity score with a consistency term whose weight grows
from sweep to sweep. Everything is vectorized over pairs and anchors: maps are int arrays
``A[i, j]`` (``(N, N, n)``, node ``u`` of graph ``i`` -> node ``A[i, j, u]`` of graph ``j``),
so ``X_ik X_kj`` is ``A[k, j][A[i, k]]``, and all candidates of a sweep are scored with a
few batched calls of the caller's ``score``.

Relation to the two public implementations (see the ``cao`` docstring for details):
``update="jacobi"`` (default) is the authors' MATLAB sweep and pygmtools' ``mode="time"``
(which implements CAO-PC); ``update="sequential"`` reproduces pygmtools' ``mode="memory"``
(CAO-C, Gauss-Seidel), including its rule of keeping the *last* anchor that beats the current
map.

Examples
--------
>>> import numpy as np
>>> from transync.multigraph import cao
>>> N, n = 4, 3
>>> pairs = np.array([(i, j) for i in range(N) for j in range(i + 1, N)])
>>> initial = np.tile(np.arange(n), (len(pairs), 1))
>>> initial[0] = [1, 0, 2]                      # graphs 0 and 1: one wrong map
>>> def score(p, a):                            # affinity: 1 per node matched to itself
...     return (a == np.arange(n)).sum(axis=1).astype(float)
>>> out = cao(initial, pairs, N, score)
>>> out.assignments[0].tolist(), out.converged, float(out.history["consistency"][-1])
([0, 1, 2], True, 1.0)
"""

from __future__ import annotations

import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass

import numpy as np

from .._progress import progress_bar
from .._validation import (check_bool, check_choice, check_int, check_int_array,
                           check_positive, check_probability)
from ._affinity import check_pairs

__all__ = ["CAOOutcome", "cao", "CAO_VARIANTS", "CAO_UPDATES"]

CAO_VARIANTS = ("cao", "cao-c", "cao-uc", "cao-pc")
CAO_UPDATES = ("jacobi", "sequential")

# Candidate entries (pairs x anchors x nodes) held at once; larger problems go in chunks.
_CHUNK_ENTRIES = 1 << 22


def _finite_mean(s: np.ndarray) -> float:
    """The mean of finite scores without overflow (scores near the float64 limit stay finite)."""
    top = float(np.max(np.abs(s))) if s.size else 0.0
    return float(np.mean(s / top) * top) if top > 0 else 0.0


@dataclass(frozen=True, slots=True)
class CAOOutcome:
    """Result of :func:`cao`.

    Attributes
    ----------
    assignments : ndarray of shape (P, n), int
        Final map of every pair, in the order of ``pairs``: node ``u`` of graph ``pairs[p, 0]``
        -> node ``assignments[p, u]`` of graph ``pairs[p, 1]``.
    scores : ndarray of shape (P,)
        ``score`` of each final map (the raw ``x^T K x``, not normalized).
    n_iter : int
        Sweeps performed (sweeps skipped because they could not change anything not counted).
    converged : bool
        Whether the last sweep changed nothing (True without any sweep when the initial maps
        are already cycle-consistent).
    history : dict of str -> ndarray
        ``"score"`` and ``"consistency"`` (length ``n_iter + 1``): mean raw score and mean
        pairwise consistency ``C_p`` of the maps before the first sweep and after each sweep
        (consistency 1.0 means cycle-consistent); ``"weight"`` (length ``n_iter``): the
        consistency weight ``lambda`` each sweep used (0 for affinity-only sweeps);
        ``"changed"`` (length ``n_iter``): number of pairs whose map changed.
    seconds : float
        Wall time of the call.
    variant : str
        The CAO variant that ran.

    Examples
    --------
    >>> import numpy as np
    >>> from transync.multigraph import cao
    >>> pairs = np.array([[0, 1], [0, 2], [1, 2]])
    >>> initial = np.array([[0, 1], [0, 1], [1, 0]])              # pair (1, 2) contradicts
    >>> def score(p_idx, assignments):                           # identity maps score best
    ...     return (assignments == np.arange(2)).sum(1).astype(float)
    >>> out = cao(initial, pairs, 3, score, variant="cao")
    >>> out.assignments.tolist()
    [[0, 1], [0, 1], [0, 1]]
    """

    assignments: np.ndarray
    scores: np.ndarray
    n_iter: int
    converged: bool
    history: Mapping[str, np.ndarray]
    seconds: float
    variant: str


def cao(initial, pairs, n_graphs: int, score: Callable, *, variant: str = "cao-pc",
        lambda_init: float = 0.3, lambda_step: float = 1.1, lambda_max: float = 1.0,
        max_iter: int = 6, immune_iter: int = 2, update: str = "jacobi",
        progress: bool = False) -> CAOOutcome:
    r"""Composition-based affinity optimization for multi-graph matching (Yan et al., 2016).

    Each sweep replaces every pairwise map by its best composition through an anchor graph:

    .. math::

        X_{ij} \leftarrow X_{ik^*} X_{k^*j}, \qquad
        k^* = \arg\max_k \; (1-\lambda)\, \frac{J_{ij}(X_{ik}X_{kj})}{J_{\max}}
              + \lambda\, C(i, j, k),

    where :math:`J_{ij}(X) = \mathrm{vec}(X)^\top K_{ij} \mathrm{vec}(X)`, :math:`J_{\max}` is
    the largest score of the current maps (pygmtools' normalization) and the consistency
    term depends on the variant, with
    :math:`C_p(X; i, j) = 1 - \sum_{l=1}^{N} \lVert X - X_{il} X_{lj} \rVert_1 / (2 N n)`:

    * ``"cao"``: affinity only (:math:`\lambda = 0`);
    * ``"cao-c"``: exact consistency of the candidate, :math:`C_p(X_{ik}X_{kj}; i, j)`;
    * ``"cao-uc"``: unary consistency of the anchor,
      :math:`C_u(k) = 1 - \operatorname{mean}_{i<j} \lVert X_{ij} - X_{ik}X_{kj} \rVert_1/(2n)`;
    * ``"cao-pc"``: pairwise consistency,
      :math:`\sqrt{C_p(X_{ik}; i, k)\, C_p(X_{kj}; k, j)}`.

    The first ``immune_iter`` sweeps use the affinity only; from sweep ``immune_iter`` on,
    :math:`\lambda \leftarrow \min(\lambda_{\max}, \text{lambda\_step}\cdot\lambda)` *before*
    each sweep (pygmtools; the authors' MATLAB code uses ``lambda_init`` itself in the first
    consistency sweep). Among equal fitness values the smallest anchor ``k`` wins.

    Parameters
    ----------
    initial : array_like of shape (P, n), int
        Initial map of every pair (e.g. pairwise RRWM), each row a permutation of ``0..n-1``.
    pairs : array_like of shape (P, 2), int
        Rows ``(i, j)``, ``i < j``: all ``N (N - 1) / 2`` pairs of the ``N`` graphs, in any
        order (CAO composes every pair through every third graph).
    n_graphs : int
        Number of graphs ``N`` (>= 2).
    score : callable ``score(p_idx, assignments) -> (c,)``
        ``x^T K_p x`` of candidate maps: ``p_idx`` (c,) indices into ``pairs``,
        ``assignments`` (c, n) int (e.g. ``PairAffinities.score_assignments``). Called once
        per sweep with every distinct candidate (or once per chunk of pairs on large problems;
        once per pair with ``update="sequential"``).
    variant : {"cao-pc", "cao", "cao-c", "cao-uc"}, default="cao-pc"
        Consistency term, see above.
    lambda_init : float in [0, 1], default=0.3
        Initial consistency weight.
    lambda_step : float >= 1, default=1.1
        Factor by which the weight grows in each consistency sweep (pygmtools; 1.0 in the
        JzMaple configuration).
    lambda_max : float in [0, 1], default=1.0
        Upper bound of the weight.
    max_iter : int, default=6
        Number of sweeps, at most 10**5.
    immune_iter : int, default=2
        Leading affinity-only sweeps (``constIterImmune`` / ``iter_boost``).
    update : {"jacobi", "sequential"}, default="jacobi"
        ``"jacobi"``: every pair is updated from the maps of the previous sweep (the authors'
        code, pygmtools ``mode="time"``); vectorized. ``"sequential"``: pairs are visited in
        the order of ``pairs`` and each sees the maps already updated in the sweep, keeping
        the *last* anchor whose fitness beats the current map, as pygmtools ``mode="memory"``
        does; one ``score`` call per pair, for reference comparisons; ``"cao"`` and
        ``"cao-c"`` only.
    progress : bool, default=False
        Show a tqdm progress bar over the sweeps.

    Returns
    -------
    CAOOutcome
        The consistent pairwise assignments of every pair, their affinity scores and the
        iterations run.

    Raises
    ------
    ValueError
        ``pairs`` not the complete set of pairs ``i < j``, ``initial`` not made of
        permutations or of the wrong shape, parameters out of range, ``score`` returning
        the wrong shape or non-finite values.
    TypeError
        ``score`` not callable, non-integer counts.

    Notes
    -----
    The fitness uses the pairwise consistency of pygmtools, which counts every anchor
    ``l`` including ``l = i, j`` (the authors' ``cal_single_pair_consistency`` skips them).
    The affinity normalization is the largest current score; when no score is positive
    the scores are used unnormalized. A sweep that could not change anything (the previous
    one changed nothing and the fitness weights are the same for every remaining sweep, or
    the maps are cycle-consistent, so that every candidate is the current map) ends the run;
    the output is then identical to running all ``max_iter`` sweeps (the authors' code also
    stops after a sweep that changed nothing while the weight would still grow; pygmtools
    never stops early). CAO runs a fixed schedule, so ``converged=False`` raises no warning.
    The outlier-aware masks of the authors' ``massOutlier`` mode are not implemented (full
    permutations only).

    References
    ----------
    J. Yan, M. Cho, H. Zha, X. Yang, S. M. Chu, "Multi-graph matching via affinity
    optimization with graduated consistency regularization", IEEE TPAMI 38(6), 2016.

    Examples
    --------
    >>> import numpy as np
    >>> pairs = np.array([(0, 1), (0, 2), (1, 2)])
    >>> initial = np.array([[1, 0], [0, 1], [0, 1]])    # 0->1 disagrees with 0->2->1
    >>> score = lambda p, a: (a == [0, 1]).sum(axis=1) + 0.0
    >>> cao(initial, pairs, 3, score, variant="cao").assignments.tolist()
    [[0, 1], [0, 1], [0, 1]]
    """
    t0 = time.perf_counter()
    N = check_int(n_graphs, "n_graphs", minimum=2, maximum=10**7)
    pairs = _check_pairs(pairs, N)
    X = _check_initial(initial, len(pairs))
    if not callable(score):
        raise TypeError(f"`score` must be callable (p_idx, assignments) -> scores, "
                        f"got {type(score).__name__}")
    variant = check_choice(variant, "variant", CAO_VARIANTS)
    update = check_choice(update, "update", CAO_UPDATES)
    if update == "sequential" and variant not in ("cao", "cao-c"):
        raise ValueError(f"`update`='sequential' (pygmtools' memory mode) supports "
                         f"variant 'cao' or 'cao-c', got variant={variant!r}")
    lambda_init = check_probability(lambda_init, "lambda_init")
    lambda_max = check_probability(lambda_max, "lambda_max")
    lambda_step = check_positive(lambda_step, "lambda_step")
    if lambda_step < 1:
        raise ValueError(f"`lambda_step` must be >= 1, got {lambda_step!r}")
    max_iter = check_int(max_iter, "max_iter", minimum=0, maximum=MAX_SWEEPS)
    immune_iter = check_int(immune_iter, "immune_iter", minimum=0)

    state = _State(X, pairs, N, score)
    schedule = _schedule(variant, max_iter, immune_iter, lambda_init, lambda_step, lambda_max)
    pc = state.pair_consistency()
    hist_score = [_finite_mean(state.scores)]
    hist_cons = [float(np.mean(pc))]
    weights, changes = [], []
    converged = False
    n_iter = 0
    last = object()                      # fitness weight of the last sweep run
    bar = progress_bar(max_iter, variant, enabled=check_bool(progress, "progress"),
                       unit="sweep")
    try:
        for t, weight in enumerate(schedule):
            if np.all(pc == 1.0):
                converged = True         # every composition is X_ij itself: nothing can change
                break
            if converged and all(w == last for w in schedule[t:]):
                break                    # the remaining sweeps would reproduce the maps
            last = weight
            if update == "jacobi":
                changed = state.sweep_jacobi(variant, weight)
            else:
                changed = state.sweep_sequential(weight)
            n_iter += 1
            converged = changed == 0
            weights.append(0.0 if weight is None else weight)
            changes.append(changed)
            hist_score.append(_finite_mean(state.scores))
            pc = state.pair_consistency()
            hist_cons.append(float(np.mean(pc)))
            bar.update(1)
    finally:
        bar.close()
    history = {"score": np.array(hist_score), "consistency": np.array(hist_cons),
               "weight": np.array(weights, dtype=float),
               "changed": np.array(changes, dtype=np.int64)}
    return CAOOutcome(assignments=state.assignments(), scores=state.scores.copy(),
                      n_iter=n_iter, converged=converged, history=history,
                      seconds=time.perf_counter() - t0, variant=variant)


# --------------------------------------------------------------------------------------------
# validation


def _check_pairs(pairs, N: int) -> np.ndarray:
    """(P, 2), 0 <= i < j < N, every pair once."""
    return check_pairs(pairs, N, complete="CAO composes every pair through every third graph; "
                                          "a partial view graph is not supported")


def _check_initial(initial, P: int) -> np.ndarray:
    arr = np.asarray(initial)
    if arr.ndim != 2 or arr.shape[0] != P or arr.shape[1] == 0:
        raise ValueError(f"`initial` must have shape (P, n) with P={P} (one row per pair) "
                         f"and n >= 1, got shape {arr.shape}")
    arr = check_int_array(arr, "initial", integral_floats=True,
                          what="integer assignments").astype(np.intp)
    n = arr.shape[1]
    ok = np.all(np.sort(arr, axis=1) == np.arange(n), axis=1)
    if not np.all(ok):
        r = int(np.flatnonzero(~ok)[0])
        raise ValueError(f"`initial` rows must be permutations of 0..{n - 1} (full matchings; "
                         f"CAO does not handle unmatched nodes), got row {r} = "
                         f"{arr[r].tolist()}")
    return arr


#: Most CAO sweeps accepted (its schedule is built up front; 2**70 never returned).
MAX_SWEEPS = 10**5


def _schedule(variant, max_iter, immune_iter, lambda_init, lambda_step, lambda_max):
    """Consistency weight of each sweep, ``None`` for affinity-only sweeps (pygmtools' order)."""
    out, lam = [], lambda_init
    for t in range(max_iter):
        if t >= immune_iter:
            lam = float(np.min([lam * lambda_step, lambda_max]))
        out.append(None if (variant == "cao" or t < immune_iter) else lam)
    return out


# --------------------------------------------------------------------------------------------
# state and sweeps


class _State:
    """All maps as an ``(N, N, n)`` table plus the scores of the maps on ``pairs``."""

    def __init__(self, X, pairs, N, score):
        self.pairs, self.N, self.score_fn = pairs, N, score
        self.I, self.J = pairs[:, 0], pairs[:, 1]
        self.P, self.n = X.shape
        self.A = np.empty((N, N, self.n), dtype=np.intp)
        self.A[np.arange(N), np.arange(N)] = np.arange(self.n)
        self._set(np.arange(self.P), X)
        self.scores = self._score(np.arange(self.P), X)
        rows = max(1, _CHUNK_ENTRIES // (N * self.n))
        self.chunks = [np.arange(s, min(s + rows, self.P)) for s in range(0, self.P, rows)]
        self._comp_cache = None

    # maps -------------------------------------------------------------------------------

    def _set(self, idx, X):
        I, J = self.I[idx], self.J[idx]
        self.A[I, J] = X
        inv = np.empty_like(X)
        inv[np.arange(len(idx))[:, None], X] = np.arange(self.n)
        self.A[J, I] = inv

    def assignments(self) -> np.ndarray:
        return self.A[self.I, self.J].astype(np.int64)

    def compositions(self, idx) -> np.ndarray:
        """``comp[c, k] = X_{i k} X_{k j}`` for the pairs ``idx``: shape (c, N, n)."""
        N, n = self.N, self.n
        base = (np.arange(N)[None, :, None] * N + self.J[idx][:, None, None]) * n  # A[k, j]
        return np.take(self.A.reshape(-1), base + self.A[self.I[idx]])

    def mismatches(self, idx, comp=None):
        """``D[c, k]``: nodes where ``X_ij`` and ``X_ik X_kj`` differ; shape (c, N)."""
        if comp is None:
            comp = self.compositions(idx)
        return np.count_nonzero(comp != self.A[self.I[idx], self.J[idx]][:, None, :], axis=2)

    def _consistency_from(self, d):
        # pygmtools' arithmetic: 1 - sum|X - X_il X_lj| / (2 n N), the L1 sum being 2 d
        return 1.0 - (2.0 * d) / (2 * self.n * self.N)

    def pair_consistency(self) -> np.ndarray:
        """``C_p(X_ij)`` of every pair (P,)."""
        return self._consistency_from(self._all_mismatches().sum(axis=1))

    def _all_mismatches(self):
        if len(self.chunks) == 1:
            comp = self.compositions(self.chunks[0])
            self._comp_cache = comp          # reused by the next sweep if maps are unchanged
            return self.mismatches(self.chunks[0], comp)
        self._comp_cache = None
        return np.concatenate([self.mismatches(c) for c in self.chunks])

    # scoring ---------------------------------------------------------------------------

    def _score(self, p_idx, assign) -> np.ndarray:
        out = self.score_fn(p_idx, assign)
        if np.iscomplexobj(out):            # numpy would drop the imaginary part with a warning
            raise TypeError("`score` must return real values, got complex ones")
        try:
            s = np.asarray(out, dtype=float)
        except (TypeError, ValueError) as exc:
            raise TypeError(f"`score` must return real numbers: {exc}") from None
        if s.shape != (len(p_idx),):
            raise ValueError(f"`score` must return an array of shape ({len(p_idx)},) for "
                             f"{len(p_idx)} candidates, got shape {s.shape}")
        if not np.all(np.isfinite(s)):
            raise ValueError("`score` must return finite values, got NaN or infinite scores")
        return s

    def score_candidates(self, idx, comp) -> np.ndarray:
        """Scores (c, N) of the candidates ``comp``; each distinct (pair, map) scored once."""
        c, N, n = comp.shape
        rows = comp.reshape(c * N, n)
        pid = np.repeat(idx, N)
        first, inverse = _distinct_rows(pid, rows)
        s = self._score(pid[first], rows[first])
        return s[inverse].reshape(c, N)

    def _norm(self) -> float:
        top = float(np.max(self.scores))
        return top if top > 0 else 1.0

    # consistency terms ---------------------------------------------------------------------

    def exact_consistency(self, comp) -> np.ndarray:
        """``C_p(X_ik X_kj; i, j)`` of every candidate (c, N), by counting votes per node."""
        c, N, n = comp.shape
        rows = (np.arange(c)[:, None, None] * n + np.arange(n)[None, None, :]) * n
        votes = np.bincount((rows + comp).reshape(-1), minlength=c * n * n)
        hits = votes[rows + comp].sum(axis=2)          # sum_u #{l : comp[l, u] == comp[k, u]}
        return self._consistency_from(n * N - hits)

    # sweeps -------------------------------------------------------------------------------

    def sweep_jacobi(self, variant, weight) -> int:
        norm = self._norm()
        pc_table = unary = None
        need_d = weight is not None and variant in ("cao-pc", "cao-uc")
        if need_d:
            D = self._all_mismatches()
            if variant == "cao-pc":
                pc = self._consistency_from(D.sum(axis=1))
                pc_table = np.ones((self.N, self.N))
                pc_table[self.I, self.J] = pc
                pc_table[self.J, self.I] = pc
            else:
                unary = 1.0 - np.mean(2.0 * D, axis=0) / (2 * self.n)
        new = np.empty((self.P, self.n), dtype=np.intp)
        new_scores = np.empty(self.P)
        cache, self._comp_cache = self._comp_cache, None
        for idx in self.chunks:
            comp = cache if (cache is not None and len(self.chunks) == 1) else \
                self.compositions(idx)
            s = self.score_candidates(idx, comp)
            fit = s / norm
            if weight is not None:
                if variant == "cao-pc":
                    con = np.sqrt(pc_table[self.I[idx]] * pc_table[:, self.J[idx]].T)
                elif variant == "cao-uc":
                    con = np.broadcast_to(unary, fit.shape)
                else:
                    con = self.exact_consistency(comp)
                fit = fit * (1 - weight) + con * weight
            best = np.argmax(fit, axis=1)
            r = np.arange(len(idx))
            new[idx] = comp[r, best]
            new_scores[idx] = s[r, best]
        changed = int(np.count_nonzero(np.any(new != self.A[self.I, self.J], axis=1)))
        self._set(np.arange(self.P), new)
        self.scores = new_scores
        return changed

    def sweep_sequential(self, weight) -> int:
        norm = self._norm()
        changed = np.zeros(self.P, dtype=bool)
        self._comp_cache = None
        for p in range(self.P):
            idx = np.array([p])
            comp = self.compositions(idx)
            s = self.score_candidates(idx, comp)[0]
            fit = s / norm
            if weight is not None:
                fit = fit * (1 - weight) + self.exact_consistency(comp)[0] * weight
            better = np.flatnonzero(fit > fit[self.I[p]])    # anchor i reproduces X_ij
            if len(better):
                k = better[-1]                               # pygmtools keeps the last one
                if np.any(comp[0, k] != self.A[self.I[p], self.J[p]]):
                    changed[p] = True
                self._set(idx, comp[0, k][None])
                self.scores[p] = s[k]
        return int(np.count_nonzero(changed))


def _distinct_rows(pid, rows, mult=None):
    """Distinct ``(pid, row)`` pairs: representatives ``first`` and ``inverse`` (rows -> rep).

    Rows are hashed to one uint64 each (a random linear hash, fast to sort); the grouping is
    verified exactly and, on a hash collision, redone with a row-wise ``np.unique``.
    """
    if mult is None:
        mult = _hash_multipliers(rows.shape[1] + 1)
    h = rows.astype(np.uint64) @ mult[1:] + pid.astype(np.uint64) * mult[0]   # wraps mod 2^64
    _, first, inverse = np.unique(h, return_index=True, return_inverse=True)
    inverse = inverse.reshape(-1)
    if np.array_equal(pid[first][inverse], pid) and np.array_equal(rows[first][inverse], rows):
        return first, inverse
    keys = np.column_stack([pid, rows])
    _, first, inverse = np.unique(keys, axis=0, return_index=True, return_inverse=True)
    return first, inverse.reshape(-1)


def _hash_multipliers(k: int) -> np.ndarray:
    return np.random.default_rng(0x0CA0).integers(1, 2**63, size=k, dtype=np.uint64) | 1
