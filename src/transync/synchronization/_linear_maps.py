"""Synchronization of invertible linear maps: the null-space method of Bernard et al. (CVPR 2015).

Convention (used everywhere in transync)
---------------------------------------
``T[i, j]`` maps coordinates of object ``j`` into object ``i``. The result stores absolute maps
``maps[i]``, which take coordinates of object ``i`` into the reference object ``r``
(``maps[r] = I``). The synchronized pairwise map is therefore

.. math:: \\hat T_{ij} = M_i^{-1} M_j ,

and a consistent input satisfies ``T[i, j] = inv(maps[i]) @ maps[j]``. In Bernard's notation
``T_ij = T_i T_j^{-1}`` with ``T_i = M_i^{-1}`` (reference frame into frame ``i``).

Method
------
With ``U = [U_1; ...; U_N]`` (``U_i = M_i^{-1} G`` for any invertible gauge ``G``), consistency
gives ``sum_j w_ij T_ij U_j = d_i U_i`` with ``d_i = sum_j w_ij``. So ``U`` spans the
``d``-dimensional null space of ``Z = D^{-1} W - I`` (``W`` holds the weighted observed blocks,
missing pairs are zero). With noise, ``U`` is taken as the ``d`` right singular vectors of ``Z``
with the smallest singular values, and the gauge is fixed by ``M_i = U_r U_i^{-1}``.

The robust variant starts from cycle-consistency scores (the median over third objects ``k`` of
the discrepancy between ``T_ik T_kj`` and ``T_ij``), then alternates the weighted null-space
solve with Cauchy reweighting of every pair by its residual (scale from the median absolute
residual) plus hard rejection of pairs far beyond that scale.
"""

from __future__ import annotations

import numbers
import warnings
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from scipy.sparse import csr_matrix
from scipy.sparse.csgraph import connected_components

from .._validation import MAX_ITER, check_array, check_bool, check_choice, check_int, check_positive
from ..exceptions import ConvergenceWarning, DegenerateInputError
from ..geometry import normalization_matrix, normalize_determinant
from ._pairwise_input import (check_mask, check_weight_keys, check_weight_magnitude, observations,
                              pair_weights)

__all__ = [
    "LinearMapSyncResult",
    "normalize_determinant",
    "synchronize_homographies",
    "synchronize_linear_maps",
]

_GROUPS = ("GL", "SL", "SO")
_RESIDUALS = ("auto", "frobenius", "corner")
_CORNERS = np.array([[-1.0, -1.0, 1.0], [1.0, -1.0, 1.0], [1.0, 1.0, 1.0], [-1.0, 1.0, 1.0]])


@dataclass(frozen=True)
class LinearMapSyncResult:
    """Result of :func:`synchronize_linear_maps` / :func:`synchronize_homographies`.

    Attributes
    ----------
    maps : ndarray of shape (N, d, d)
        ``maps[i]`` maps coordinates of object ``i`` into the reference object
        (``maps[reference]`` is the identity). Views outside the reference's connected
        component (only with ``disconnected="component"``) hold NaN.
    reference : int
        Index of the reference object.
    group : str
        ``"GL"``, ``"SL"`` or ``"SO"``.
    mask : ndarray of shape (N, N), bool
        Observed pairs after symmetrization (``T[j, i] = inv(T[i, j])`` filled in).
    weights : ndarray of shape (N, N)
        Final weights of the observed pairs (input weights times robust weights; 0 = rejected).
    inliers : ndarray of shape (N, N), bool
        Observed pairs that were not rejected.
    residuals : ndarray of shape (N, N)
        Residual of every observed pair against the synchronized pairwise map (NaN elsewhere);
        corner transfer error (pixels for :func:`synchronize_homographies`) or relative
        Frobenius error, see ``info["residual"]``.
    objective : float
        Weighted mean squared residual over the kept pairs whose residual is finite (a corner
        residual is infinite when one of the two maps sends a corner of the unit square to the
        line at infinity; ``residuals`` shows it); ``inf`` only when every kept pair's is.
    n_iter : int
        Number of null-space solves (1 without ``robust``).
    converged : bool
    info : dict
        ``singular_values`` (the d + 1 smallest of Z), ``spectral_gap``, ``residual``,
        ``components`` (component label per object), ``excluded`` (objects outside the
        reference's component), ``history`` (max map change per IRLS iteration).

    Examples
    --------
    >>> from transync.datasets import make_noisy_linear_maps
    >>> from transync.synchronization import synchronize_linear_maps
    >>> prob = make_noisy_linear_maps(n_objects=5, noise=0.0, rng=0)
    >>> res = synchronize_linear_maps(prob.observed, mask=prob.mask)
    >>> res.maps.shape, res.reference, res.group
    ((5, 3, 3), 0, 'GL')
    """

    maps: np.ndarray
    reference: int
    group: str
    mask: np.ndarray
    weights: np.ndarray
    inliers: np.ndarray
    residuals: np.ndarray
    objective: float
    n_iter: int
    converged: bool
    info: Mapping[str, Any] = field(default_factory=dict)

    @property
    def n_objects(self) -> int:
        return int(self.maps.shape[0])

    def pairwise(self, i: int, j: int) -> np.ndarray:
        """Synchronized map from object ``j`` into object ``i``: ``inv(maps[i]) @ maps[j]``."""
        n = self.n_objects
        i = check_int(i, "i", minimum=0, maximum=n - 1)
        j = check_int(j, "j", minimum=0, maximum=n - 1)
        out = np.linalg.solve(self.maps[i], self.maps[j])
        if self.group == "SL":
            out = normalize_determinant(out)
        return out

    def to_array(self) -> np.ndarray:
        """All synchronized pairwise maps as an (N, N, d, d) array (cycle-consistent)."""
        inv = np.linalg.inv(self.maps)
        out = np.einsum("iab,jbc->ijac", inv, self.maps)
        if self.group == "SL":
            out = normalize_determinant(out)
        return out


# ----------------------------------------------------------------------------------------------
# helpers
# ----------------------------------------------------------------------------------------------
def _residual(A, B, kind: str) -> np.ndarray:
    """Discrepancy between stacks of maps A and B (``B`` is the estimate); shape A.shape[:-2]."""
    if kind == "corner":
        pa = np.einsum("...ab,kb->...ka", A, _CORNERS)
        pb = np.einsum("...ab,kb->...ka", B, _CORNERS)
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
            pa = pa[..., :2] / pa[..., 2:3]
            pb = pb[..., :2] / pb[..., 2:3]
            r = np.linalg.norm(pa - pb, axis=-1).mean(axis=-1)
        return np.where(np.isfinite(r), r, np.inf)      # a corner sent to the line at infinity
    num = np.linalg.norm(A - B, axis=(-2, -1))
    den = np.linalg.norm(B, axis=(-2, -1))
    return num / np.maximum(den, 1e-300)


_MAX_ND = 20000   # the null-space method factorizes an (N d) x (N d) matrix
_MIN_IMAGE_SIZE, _MAX_IMAGE_SIZE = 1e-6, 1e9     # image sizes synchronize_homographies takes
_MAX_SCALE = 1e100  # observed maps with singular values beyond [1e-100, 1e100] overflow


def _triples_as_dict(T, name: str):
    """A list of ``(i, j, map)`` triples as ``{(i, j): map}``; anything else unchanged."""
    if isinstance(T, (list, tuple)) and T and all(
            isinstance(e, (list, tuple)) and len(e) == 3 and isinstance(e[0], numbers.Integral)
            and isinstance(e[1], numbers.Integral) for e in T):
        out = {}
        for k, (i, j, M) in enumerate(T):
            if (i, j) in out:
                raise ValueError(f"`{name}[{k}]` repeats the pair {(int(i), int(j))}")
            out[(i, j)] = M
        return out
    return T


def _parse_input(T, mask, n_objects, name="T"):
    """Dense ``(N, N, d, d)`` maps and the observed entries, from an array, a dict or triples.

    ``mask`` has the meaning of every synchronization function (see
    ``_pairwise_input``): it selects pairs; a dense array is read in each masked direction.
    """
    T = _triples_as_dict(T, name)
    if not isinstance(T, (np.ndarray, Mapping)):
        T = check_array(T, name, finite=False)
    if isinstance(T, np.ndarray):
        T = check_array(T, name, ndim=4, finite=False)
        n, n2, d, d2 = T.shape
        if n != n2 or d != d2 or d == 0:
            raise ValueError(f"`{name}` must have shape (N, N, d, d) with d >= 1, got shape "
                             f"{T.shape}")
        if n == 0:
            raise ValueError(f"`{name}` must hold at least one object, got shape {T.shape}")
        _check_size(n, d, name)
        if n_objects is not None and check_int(n_objects, "n_objects", minimum=1) != n:
            raise ValueError(f"`n_objects` must match the {n} objects of the array `{name}` "
                             f"(or be None), got {n_objects}")
        mask = check_mask(mask, n, against=name)
        obs = ~np.eye(n, dtype=bool) if mask is None else mask
        bad = obs & ~np.all(np.isfinite(T), axis=(-2, -1))
        if bad.any():
            i, j = np.argwhere(bad)[0]
            raise ValueError(f"`{name}[{i}, {j}]` must be finite where observed, got NaN or "
                             "infinite entries")
        return T, obs.copy()
    mask = check_mask(mask)
    items = observations(T, mask, name=name, dense_both=True)
    if not items:
        raise ValueError(f"`{name}` must contain at least one pair, got none" if mask is None
                         else f"`mask` selects no pair of `{name}`")
    n = max(max(i, j) for i, j, _ in items) + 1
    if n_objects is not None:
        n_objects = check_int(n_objects, "n_objects", minimum=1)
        if n > n_objects:
            raise ValueError(f"`{name}` has a pair index {n - 1} but `n_objects` is {n_objects}")
        n = n_objects
    if mask is not None and mask.shape[0] > n:
        n = mask.shape[0]
    first = check_array(items[0][2], f"{name}[{items[0][:2]}]", ndim=2)
    d = first.shape[0]
    if d == 0 or first.shape != (d, d):
        raise ValueError(f"`{name}[{items[0][:2]}]` must be a square (d, d) matrix with "
                         f"d >= 1, got shape {first.shape}")
    _check_size(n, d, name)
    dense = np.zeros((n, n, d, d))
    obs = np.zeros((n, n), dtype=bool)
    for i, j, Tij in items:
        Tij = check_array(Tij, f"{name}[{(i, j)}]", ndim=2)
        if Tij.shape != (d, d):
            raise ValueError(f"`{name}[{(i, j)}]` must have shape ({d}, {d}) like the first pair, "
                             f"got shape {Tij.shape}")
        dense[i, j] = Tij
        obs[i, j] = True
    return dense, obs


def _check_size(n: int, d: int, name: str = "T") -> None:
    if n * d > _MAX_ND:
        raise ValueError(f"`{name}` holds {n} objects of dimension {d}: the null-space method "
                         f"factorizes an (N d) x (N d) matrix, N d = {n * d} > {_MAX_ND}; "
                         "renumber the objects without gaps or split the problem")


def _check_invertible(T, obs, name="T"):
    idx = np.argwhere(obs)
    if idx.size == 0:
        return
    blocks = T[obs]
    sv = np.linalg.svd(blocks, compute_uv=False)
    ok = sv[:, -1] > 1e-12 * sv[:, 0]                     # all-zero blocks fail too
    bad = np.flatnonzero(~ok)
    if bad.size:
        i, j = idx[bad[0]]
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
            cond = sv[bad[0], 0] / sv[bad[0], -1] if sv[bad[0], -1] > 0 else np.inf
        raise ValueError(f"`{name}[{i}, {j}]` must be invertible, got a singular matrix "
                         f"(condition number {cond:.3g}); {bad.size} singular pair(s)")
    scaled = np.flatnonzero((sv[:, 0] > _MAX_SCALE) | (sv[:, -1] < 1 / _MAX_SCALE))
    if scaled.size:
        q = scaled[0]
        i, j = idx[q]
        raise ValueError(f"`{name}[{i}, {j}]` must have singular values within "
                         f"[{1 / _MAX_SCALE:.0e}, {_MAX_SCALE:.0e}], got {sv[q, -1]:.3g} .. "
                         f"{sv[q, 0]:.3g}; rescale the coordinates")


def _symmetrize(T, obs, weights):
    """Fill T[j, i] = inv(T[i, j]) where only one direction was observed; symmetric weights."""
    T = T.copy()
    only = obs & ~obs.T
    if only.any():
        i, j = np.nonzero(only)
        T[j, i] = np.linalg.inv(T[i, j])
    full = obs | obs.T
    if weights is None:
        w = full.astype(float)
    else:
        w = np.where(obs, weights, 0.0)
        w = np.where(obs & obs.T, 0.5 * (w + w.T), np.maximum(w, w.T))
        w = np.where(full, w, 0.0)
    return T, full, w


def _nullspace(T, w, d):
    """Smallest right singular vectors of Z = D^{-1} W - I; returns U (N, d, d) and sigma."""
    n = T.shape[0]
    deg = w.sum(axis=1)
    blocks = np.where((w > 0)[:, :, None, None], T, 0.0)
    Z = (w[:, :, None, None] * blocks / deg[:, None, None, None]).transpose(0, 2, 1, 3)
    Z = Z.reshape(n * d, n * d) - np.eye(n * d)
    _, s, vt = np.linalg.svd(Z)
    U = vt[-d:].T.reshape(n, d, d)
    return U, s[::-1][: d + 1]


def _maps_from_nullspace(U, reference, group):
    Ur = U[reference]
    cond = np.linalg.cond(Ur)
    if not cond < 1e12:
        raise DegenerateInputError(
            f"the reference block of the null space is singular (condition {cond:.3g}); the "
            "observations do not determine the maps")
    if group == "SO":
        # project the blocks first, then fix the gauge: the null-space basis is unique up to
        # an orthogonal d x d factor, which commutes with the projection, so the pairwise maps
        # do not depend on the reference (projecting Ur U_i^-1 instead made them depend on it
        # under noise, by up to 1.5e-3 at noise 0.05; metamorphic test)
        if np.sum(np.linalg.det(U) < 0) > U.shape[0] / 2:
            U = U * np.r_[np.ones(U.shape[-1] - 1), -1.0]    # a reflection of the basis
        R = _project(U, "SO")
        return R[reference][None] @ np.swapaxes(R, 1, 2)
    conds = np.linalg.cond(U)
    bad = np.flatnonzero(~(conds < 1e12))
    if bad.size:
        raise DegenerateInputError(
            f"the null-space block of object {int(bad[0])} is singular (condition "
            f"{conds[bad[0]]:.3g}; {bad.size} object(s)); the observations do not determine "
            "its map (they are far from consistent: the two directions of a pair should be "
            "about each other's inverse)")
    maps = Ur[None] @ np.linalg.inv(U)
    return _project(maps, group)


def _project(maps, group):
    if group == "SL":
        return normalize_determinant(maps)
    if group == "SO":
        u, _, vt = np.linalg.svd(maps)
        det = np.linalg.det(u @ vt)
        u[..., :, -1] *= np.sign(det)[..., None]
        return u @ vt
    return maps


def _pair_residuals(T, obs, maps, kind):
    inv = np.linalg.inv(maps)
    est = np.einsum("iab,jbc->ijac", inv, maps)
    r = np.full(obs.shape, np.nan)
    T = np.where(obs[:, :, None, None], T, 0.0)
    if kind == "corner":
        r[obs] = _residual(normalize_determinant(T[obs], singular_tol=0),
                           normalize_determinant(est[obs], singular_tol=0), kind)
    else:
        r[obs] = _residual(T[obs], est[obs], kind)
    return r


def _cycle_scores(T, obs, kind):
    """Median over k of the discrepancy between T_ik T_kj and T_ij (NaN when no triangle)."""
    n = T.shape[0]
    scores = np.full((n, n), np.nan)
    for i in range(n):
        js = np.flatnonzero(obs[i])
        if js.size == 0:
            continue
        ks = np.flatnonzero(obs[i])
        # P[k, j] = T[i, k] @ T[k, j]
        P = np.einsum("kab,kjbc->kjac", T[i, ks], T[ks][:, js])
        valid = obs[ks][:, js] & (ks[:, None] != js[None, :])
        ref = np.broadcast_to(T[i, js][None], P.shape)
        if kind == "corner":
            res = _residual(normalize_determinant(P, singular_tol=0),
                            normalize_determinant(ref, singular_tol=0), kind)
        else:
            res = _residual(P, ref, kind)
        res = np.where(valid, res, np.nan)
        has = valid.any(axis=0)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)
            med = np.nanmedian(np.where(has[None], res, 0.0), axis=0)
        scores[i, js] = np.where(has, med, np.nan)
    return scores


def _robust_weights(r, obs, scale_floor, c=2.385, reject=4.0):
    """Cauchy weights from residuals (symmetrized); hard zero beyond ``reject`` robust sigmas."""
    rs = np.where(obs, r, np.nan)
    rs = np.where(np.isnan(rs.T), rs, 0.5 * (rs + rs.T))
    vals = rs[obs]
    vals = vals[np.isfinite(vals)]
    if vals.size == 0:
        return np.where(obs, 1.0, 0.0), scale_floor
    sigma = max(1.4826 * float(np.median(vals)), scale_floor)
    u = np.where(np.isfinite(rs), rs, 0.0) / (c * sigma)
    w = 1.0 / (1.0 + u ** 2)
    w = np.where(np.isfinite(rs) & (rs > reject * c * sigma), 0.0, w)
    w = np.where(np.isinf(rs), 0.0, w)
    return np.where(obs, w, 0.0), sigma


def _components(obs):
    n_comp, labels = connected_components(csr_matrix(obs), directed=False)
    return n_comp, labels


def _keep_connected(w_new, w_fallback, obs):
    """Use ``w_new`` unless its support disconnects the observation graph; then restore edges."""
    support = (w_new > 0) & obs
    n_comp, _ = _components(support)
    if n_comp == 1:
        return w_new
    # restore rejected edges, strongest first, until connected. Each one restored joins two
    # components, so it is a bridge of the support: no cycle checks it and a lower weight buys no
    # robustness, while a tiny one (1e-3 of it, or an absolute 1e-6 that broke the invariance to
    # the weights' scale) nearly splits the null space and spoiled the fit of trees
    # (residual 0.16 -> 275); they keep their own weight
    out = w_new.copy()
    upper = np.arange(obs.shape[0])[:, None] < np.arange(obs.shape[0])
    rejected = np.argwhere(obs & ~support & upper)
    order = np.argsort(-w_fallback[rejected[:, 0], rejected[:, 1]])
    for k in order:
        i, j = rejected[k]
        n_before, lab = _components((out > 0) & obs)
        if lab[i] != lab[j]:
            out[i, j] = out[j, i] = w_fallback[i, j]
            if _components((out > 0) & obs)[0] == 1:
                break
    return out


# ----------------------------------------------------------------------------------------------
# front doors
# ----------------------------------------------------------------------------------------------
def synchronize_linear_maps(T, *, mask=None, weights=None, reference=0, group="GL",
                            robust=False, residual="auto", max_iter=20, tol=1e-8,
                            disconnected="raise", n_objects=None,
                            residual_scale=1.0) -> LinearMapSyncResult:
    """Synchronize pairwise invertible linear maps with the null-space method (Bernard et al.).

    .. math:: \\min_{U^T U = I} \\| (D^{-1} W - I)\\, U \\|_F ,\\qquad M_i = U_r U_i^{-1}

    Parameters
    ----------
    T : ndarray of shape (N, N, d, d) or dict {(i, j): ndarray (d, d)}
        ``T[i, j]`` maps coordinates of object ``j`` into object ``i``. Entries outside ``mask``
        are ignored. Where only one direction of a pair is observed, the other is its inverse.
    mask : ndarray of shape (N, N), bool, default=None
        The pairs to use (default: every pair): pair ``{i, j}`` is used when ``mask[i, j]`` or
        ``mask[j, i]``, for a dict as for an array (the same meaning in every synchronization
        function); an array is read in each direction whose entry is True, a direction left
        out is the inverse of the other. The diagonal is ignored.
    weights : ndarray of shape (N, N) or dict {(i, j): float}, default=None
        Non-negative confidence per observed pair (e.g. inlier counts); default all ones. A
        dict is read in either direction and needs an entry for every observed pair.
    reference : int, default=0
        Gauge: ``maps[reference]`` is the identity.
    group : {"GL", "SL", "SO"}, default="GL"
        ``"SL"`` normalizes every map to determinant 1 (homographies when d = 3); ``"SO"``
        projects the null-space blocks to rotations before fixing the gauge (rotation
        averaging; the pairwise maps do not depend on ``reference``).
    robust : bool, default=False
        Cycle-consistency initial weights, then IRLS with Cauchy weights on the pair residuals
        (scale by the median absolute residual) and hard rejection beyond 4 robust scales.
    residual : {"auto", "frobenius", "corner"}, default="auto"
        Pair residual for the robust weights and ``result.residuals``. ``"corner"``: mean
        transfer error of the corners (+-1, +-1) (projective, d = 3; coordinates should be
        normalized to about [-1, 1]); ``"frobenius"``: ``||T - T_hat||_F / ||T_hat||_F``.
        ``"auto"`` is ``"frobenius"``; :func:`synchronize_homographies` uses ``"corner"``.
    max_iter : int, default=20
        Maximum number of IRLS iterations (``robust=True``).
    tol : float, default=1e-8
        IRLS stops when no map moves more than this (in the residual's units).
    disconnected : {"raise", "component"}, default="raise"
        What to do when the observed pairs do not connect all objects: raise
        :class:`~transync.exceptions.DegenerateInputError`, or synchronize the reference's
        component and give NaN maps to the other objects (listed in ``info["excluded"]``).
    n_objects : int, default=None
        Number of objects when ``T`` is a dict (default: largest index + 1); for an array it
        must be None or its N.
    residual_scale : float or array of shape (N,), default=1.0
        Factor applied to the reported residuals (e.g. pixels per normalized unit); an array
        gives one factor per object, applied to the residuals of the pairs ``(i, j)`` of row
        ``i`` (a pair's residual lives in object ``i``).

    Returns
    -------
    LinearMapSyncResult
        The synchronized absolute maps (normalized as requested) and the consistent pairwise
        maps they imply.

    Raises
    ------
    ValueError
        Mismatched shapes, self-pairs, non-finite or singular maps, bad weights.
    DegenerateInputError
        Disconnected observation graph (with ``disconnected="raise"``).

    References
    ----------
    F. Bernard, J. Thunberg, P. Gemmar, F. Hertel, A. Husch, J. Goncalves, "A solution for
    multi-alignment by transformation synchronisation", CVPR 2015.

    Examples
    --------
    >>> import numpy as np
    >>> from transync.synchronization import synchronize_linear_maps
    >>> rng = np.random.default_rng(0)
    >>> M = rng.normal(size=(4, 3, 3)) + 3 * np.eye(3)     # object i -> reference (up to gauge)
    >>> T = np.einsum("iab,jbc->ijac", np.linalg.inv(M), M)  # T[i, j] = M_i^-1 M_j
    >>> res = synchronize_linear_maps(T)
    >>> bool(np.allclose(res.pairwise(1, 3), T[1, 3]))
    True
    >>> bool(np.allclose(res.maps[0], np.eye(3)))
    True
    """
    return _synchronize_linear_maps(
        T, name="T", mask=mask, weights=weights, reference=reference, group=group,
        robust=robust, residual=residual, max_iter=max_iter, tol=tol,
        disconnected=disconnected, n_objects=n_objects, residual_scale=residual_scale)


def _synchronize_linear_maps(T, *, name, mask, weights, reference, group, robust, residual,
                             max_iter, tol, disconnected, n_objects,
                             residual_scale) -> LinearMapSyncResult:
    """:func:`synchronize_linear_maps`, its messages naming the maps ``name`` (the caller's
    argument: ``H`` for :func:`synchronize_homographies`)."""
    group = check_choice(group, "group", _GROUPS)
    residual = check_choice(residual, "residual", _RESIDUALS)
    disconnected = check_choice(disconnected, "disconnected", ("raise", "component"))
    max_iter = check_int(max_iter, "max_iter", minimum=1, maximum=MAX_ITER)
    tol = check_positive(tol, "tol", allow_zero=True)
    per_object = np.ndim(residual_scale) > 0
    if per_object:
        residual_scale = check_array(residual_scale, "residual_scale", ndim=1)
        if residual_scale.size and residual_scale.min() <= 0:
            raise ValueError(f"`residual_scale` must be positive, got "
                             f"{float(residual_scale.min())!r}")
    else:
        residual_scale = check_positive(residual_scale, "residual_scale")
    check_bool(robust, "robust")
    T, obs = _parse_input(T, mask, n_objects, name)
    n, d = T.shape[0], T.shape[-1]
    if per_object and residual_scale.shape != (n,):
        raise ValueError(f"`residual_scale` must be a number or hold one factor per object "
                         f"({n}), got shape {residual_scale.shape}")
    reference = check_int(reference, "reference", minimum=0, maximum=n - 1)
    if group == "SO" and d not in (2, 3):
        raise ValueError(f"`group='SO'` needs d = 2 or 3, got d = {d}")
    if residual == "auto":
        residual = "frobenius"
    if residual == "corner" and d != 3:
        raise ValueError(f"`residual='corner'` needs 3x3 maps, got d = {d}")
    T, obs, w0 = _prepare_observations(T, obs, weights, group, mask_given=mask is not None,
                                        name=name)
    keep, excluded, labels = _reference_component(obs, reference, disconnected)
    Tk = T[np.ix_(keep, keep)]
    ok = obs[np.ix_(keep, keep)]
    ref_k = int(np.flatnonzero(keep == reference)[0])
    maps_k, w, sv, n_iter, converged, history = _solve(
        Tk, ok, w0[np.ix_(keep, keep)], ref_k, group=group, residual=residual, robust=robust,
        max_iter=max_iter, tol=tol)
    maps = np.full((n, d, d), np.nan)
    maps[keep] = maps_k
    r_k = _pair_residuals(Tk, ok, maps_k, residual) * (
        residual_scale[keep][:, None] if per_object else residual_scale)
    residuals = np.full((n, n), np.nan)
    residuals[np.ix_(keep, keep)] = r_k
    weights_out = np.zeros((n, n))
    weights_out[np.ix_(keep, keep)] = w
    inliers = obs & (weights_out > 1e-5 * max(float(weights_out.max()), 1e-300))
    kept = (w > 0) & ok
    finite = kept & np.isfinite(r_k)        # corner residuals: inf when a corner goes to infinity
    # weights relative to the largest: only their ratios matter, and w * r**2 overflowed
    # for weights ~1e250 (inf objective from finite residuals)
    wf = w[finite] / max(float(w[finite].max(initial=0.0)), 1e-300)
    objective = (float(np.sum(wf * r_k[finite] ** 2) / max(np.sum(wf), 1e-300))
                 if finite.any() or not kept.any() else np.inf)
    info = {
        "singular_values": sv,
        "spectral_gap": float(sv[d] / max(sv[d - 1], 1e-300)) if len(sv) > d else np.inf,
        "residual": residual,
        "components": labels,
        "excluded": excluded,
        "history": history,
    }
    return LinearMapSyncResult(maps=maps, reference=reference, group=group, mask=obs,
                               weights=weights_out, inliers=inliers, residuals=residuals,
                               objective=objective, n_iter=n_iter, converged=converged, info=info)


def _prepare_observations(T, obs, weights, group, *, mask_given, name="T"):
    """Weights, invertibility, SL(d) scaling and the missing directions (inverses)."""
    n, d = T.shape[0], T.shape[-1]
    if isinstance(weights, Mapping):     # dict {(i, j): w}, read for every observed direction
        check_weight_keys(weights, n)
        ki, kj = np.nonzero(obs)
        dense = np.zeros((n, n))
        dense[ki, kj] = pair_weights(weights, ki, kj)
        weights = dense
    if weights is not None:
        weights = check_array(weights, "weights", ndim=2)
        if weights.shape != (n, n):
            raise ValueError(f"`weights` must have shape ({n}, {n}) to match `{name}`, "
                             f"got shape {weights.shape}")
        if weights.size and weights.min() < 0:
            raise ValueError(f"`weights` must be non-negative, got {float(weights.min())}")
        obs = obs & (weights > 0)
        check_weight_magnitude(weights[obs], d * d)
    if not obs.any():
        what = "`mask` and `weights` select" if mask_given or weights is not None else "it holds"
        raise ValueError(f"`{name}` must hold at least one observed pair i != j, but {what} none "
                         f"({n} object(s))")
    if group == "SL":            # scale-free group: rescale blocks of extreme magnitude
        top = np.abs(T[obs]).max(axis=(-2, -1), keepdims=True)
        extreme = (top > 1e50) | ((top < 1e-50) & (top > 0))
        if extreme.any():
            T = T.copy()
            T[obs] = np.where(extreme, T[obs] / np.where(extreme, top, 1.0), T[obs])
    _check_invertible(T, obs, name)
    if group == "SL":
        det = np.linalg.det(T[obs])
        if d % 2 == 0 and np.any(det < 0):
            i, j = np.argwhere(obs)[np.flatnonzero(det < 0)[0]]
            raise ValueError(f"`{name}[{i}, {j}]` has a negative determinant, which no "
                             f"scaling maps into SL({d})")
        T = T.copy()
        T[obs] = normalize_determinant(T[obs])
    T, obs, w0 = _symmetrize(T, obs, weights)
    T = np.where(obs[:, :, None, None], T, np.eye(d))
    return T, obs, w0


def _reference_component(obs, reference, disconnected):
    """Objects of the reference's component (``keep``), the others and the component labels."""
    n = obs.shape[0]
    n_comp, labels = _components(obs)
    if n_comp == 1:
        return np.arange(n), np.array([], dtype=int), labels
    sizes = np.bincount(labels)
    comps = [np.flatnonzero(labels == c).tolist() for c in range(n_comp)]
    if disconnected == "raise":
        raise DegenerateInputError(
            f"the observation graph is disconnected: {n_comp} components "
            f"(sizes {sizes.tolist()}): {comps if n <= 30 else '...'}; maps between "
            "components are undetermined (use disconnected='component' to synchronize the "
            "reference's component only)")
    return (np.flatnonzero(labels == labels[reference]),
            np.flatnonzero(labels != labels[reference]), labels)


def _solve(Tk, ok, wk0, ref_k, *, group, residual, robust, max_iter, tol):
    """Null-space solve on one connected component, with IRLS when ``robust``."""
    d = Tk.shape[-1]
    history: list[float] = []
    w = wk0.copy()
    if Tk.shape[0] == 1:
        return np.eye(d)[None], w, np.zeros(d + 1), 0, True, history
    if robust:
        cs = _cycle_scores(Tk, ok, residual)
        fill = np.nanmedian(cs[ok]) if np.isfinite(cs[ok]).any() else 0.0
        w_c, _ = _robust_weights(np.where(np.isnan(cs), fill, cs), ok, 1e-9)
        w = _keep_connected(wk0 * w_c, wk0, ok)
    U, sv = _nullspace(Tk, w, d)
    maps_k = _maps_from_nullspace(U, ref_k, group)
    n_iter = 1
    if not robust:
        return maps_k, w, sv, n_iter, True, history
    converged = False
    for _ in range(max_iter):
        r = _pair_residuals(Tk, ok, maps_k, residual)
        w_r, _ = _robust_weights(r, ok, 1e-9)
        w = _keep_connected(wk0 * w_r, wk0, ok)
        U, sv = _nullspace(Tk, w, d)
        new = _maps_from_nullspace(U, ref_k, group)
        n_iter += 1
        change = float(np.max(_residual(new, maps_k, residual)))
        history.append(change)
        maps_k = new
        if change <= tol:
            converged = True
            break
    if not converged:
        warnings.warn(f"robust synchronization did not converge in {max_iter} iterations "
                      f"(last change {history[-1]:.3g})", ConvergenceWarning, stacklevel=3)
    return maps_k, w, sv, n_iter, converged, history


def _image_sizes(image_size, n):
    if image_size is None:
        return None
    arr = check_array(image_size, "image_size", ndim=(1, 2))
    if arr.shape == (2,):
        arr = np.broadcast_to(arr, (n, 2))
    if arr.shape != (n, 2) or not np.all(arr > 0):
        raise ValueError(f"`image_size` must be (width, height) or an array of shape ({n}, 2) "
                         f"with positive entries, got {np.asarray(image_size).tolist()!r:.80}")
    if arr.min() < _MIN_IMAGE_SIZE or arr.max() > _MAX_IMAGE_SIZE:
        raise ValueError(f"`image_size` must lie in [{_MIN_IMAGE_SIZE:g}, {_MAX_IMAGE_SIZE:g}] "
                         f"(pixels), got {arr.min():.3g} .. {arr.max():.3g}: the normalized "
                         "homographies would lose their digits")
    return arr


def synchronize_homographies(H, *, mask=None, weights=None, reference=0, robust=False,
                             image_size=None, max_iter=50, tol=1e-6,
                             disconnected="raise") -> LinearMapSyncResult:
    """Synchronize pairwise plane homographies (SL(3) null-space method) in normalized coordinates.

    ``H[i, j]`` maps pixel coordinates of view ``j`` into view ``i``; the result's ``maps[i]``
    maps pixels of view ``i`` into the reference view, scaled to determinant 1.

    Each ``H[i, j]`` is conjugated into a Hartley-normalized frame
    (``N_i H_ij N_j^{-1}``, with ``N`` taking each image to about [-1, 1]) before
    :func:`synchronize_linear_maps` with ``group="SL"``; otherwise the entries of pixel
    homographies differ by orders of magnitude and the null space is ill-conditioned.

    Parameters
    ----------
    H : ndarray of shape (N, N, 3, 3) or dict {(i, j): ndarray (3, 3)}
    mask, weights, reference, robust, disconnected
        As in :func:`synchronize_linear_maps`.
    max_iter : int, default=50
        IRLS iterations when ``robust`` (:func:`synchronize_linear_maps`'s default is 20). The
        IRLS converges linearly, and on real matches the change can shrink by only ~0.7 per
        iteration: with OpenCV 5's SIFT, one synchronization of a generated 4-view scene
        needed 22 iterations to reach ``tol`` (it stopped unconverged at 20).
    image_size : (width, height) or ndarray of shape (N, 2), default=None
        Image sizes for the normalization. ``None`` means the coordinates are used as given
        (they should then already be about [-1, 1]).
    tol : float, default=1e-6
        IRLS tolerance in normalized units.

    Returns
    -------
    LinearMapSyncResult
        ``residuals`` are mean corner transfer errors, in pixels when ``image_size`` is given:
        measured at the corners of the square that the normalization maps to
        ``[-1, 1]^2`` (half its side is half the longer image side, so it encloses the
        image; for 640 x 480 it runs over y = -80 .. 560), hence somewhat above
        :func:`transync.metrics.corner_error` on the image's own corners.

    Raises
    ------
    ValueError, TypeError
        As :func:`synchronize_linear_maps` (naming ``H``), and image sizes outside
        [1e-6, 1e9].
    DegenerateInputError
        Disconnected observation graph (with ``disconnected="raise"``).

    Examples
    --------
    >>> import numpy as np
    >>> from transync.synchronization import synchronize_homographies
    >>> from transync.datasets import make_noisy_homographies
    >>> prob = make_noisy_homographies(n_views=6, noise=0.0, rng=0)
    >>> res = synchronize_homographies(prob.observed, mask=prob.mask, image_size=prob.image_size)
    >>> from transync.homography import corner_error
    >>> bool(corner_error(res.maps, prob.truth, image_size=prob.image_size).max() < 1e-6)
    True
    """
    H = _triples_as_dict(H, "H")
    if isinstance(H, Mapping):
        if not H:
            raise ValueError("`H` must contain at least one pair, got an empty dict")
        if not all(isinstance(key, tuple) and len(key) == 2 for key in H):
            raise TypeError("`H` keys must be pairs (i, j) of view indices, got "
                            f"{next(k for k in H if not (isinstance(k, tuple) and len(k) == 2))!r}")
        n = max(check_int(k, "H key", minimum=0) for key in H for k in key) + 1
        _check_size(n, 3, "H")
        for (i, j), Hij in H.items():
            Hij = check_array(Hij, f"H[{(i, j)}]", ndim=2, finite=False)
            if Hij.shape != (3, 3):
                raise ValueError(f"`H[{(i, j)}]` must have shape (3, 3), got {Hij.shape}")
    else:
        H = check_array(H, "H", ndim=4, finite=False)
        n = H.shape[0]
        if n == 0:
            raise ValueError(f"`H` must hold at least one view, got shape {H.shape}")
    sizes = _image_sizes(image_size, n)
    scale = 1.0
    if sizes is not None:
        Nm = np.stack([normalization_matrix(s) for s in sizes])
        Ninv = np.linalg.inv(Nm)
        if isinstance(H, Mapping):
            Hn = {}
            for (i, j), Hij in H.items():
                Hij = check_array(Hij, f"H[{(i, j)}]", ndim=2)
                if Hij.shape != (3, 3):
                    raise ValueError(f"`H[{(i, j)}]` must have shape (3, 3), got {Hij.shape}")
                Hn[(i, j)] = Nm[i] @ Hij @ Ninv[j]
        else:
            if H.shape[1:] != (n, 3, 3):
                raise ValueError(f"`H` must have shape (N, N, 3, 3), got shape {H.shape}")
            Hn = np.einsum("iab,ijbc,jcd->ijad", Nm, np.nan_to_num(H), Ninv)
            Hn = np.where(np.isfinite(H).all(axis=(-2, -1))[..., None, None], Hn, np.nan)
        # pair (i, j)'s corner residual lives in view i: its pixels per normalized unit
        scale = np.max(sizes, axis=1) / 2.0
    else:
        Hn = H
        if not isinstance(H, Mapping) and H.shape[1:] != (n, 3, 3):
            raise ValueError(f"`H` must have shape (N, N, 3, 3), got shape {H.shape}")
    res = _synchronize_linear_maps(Hn, name="H", mask=mask, weights=weights,
                                   reference=reference, group="SL", robust=robust,
                                   residual="corner", max_iter=max_iter, tol=tol,
                                   disconnected=disconnected,
                                   n_objects=n if isinstance(H, Mapping) else None,
                                   residual_scale=scale)
    if sizes is None:
        return res
    maps = normalize_determinant(np.einsum("ab,ibc,icd->iad", Ninv[res.reference], res.maps, Nm))
    ok = np.isfinite(res.maps).all(axis=(-2, -1))
    maps[~ok] = np.nan
    info = dict(res.info)
    info["normalization"] = Nm
    return LinearMapSyncResult(maps=maps, reference=res.reference, group="SL", mask=res.mask,
                               weights=res.weights, inliers=res.inliers,
                               residuals=res.residuals, objective=res.objective,
                               n_iter=res.n_iter, converged=res.converged, info=info)
