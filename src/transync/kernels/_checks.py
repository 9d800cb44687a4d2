"""Input checks shared by the kernels' modules."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from .._validation import check_array

__all__ = ["check_feature_list"]


def check_feature_list(features, name: str = "features") -> list[np.ndarray]:
    """One ``(n_i, f)`` float array per graph (``n_i >= 1``, one ``f`` for all), validated.

    A padded ``(N, n, f)`` array is refused: its rows would all count as real nodes.
    """
    if isinstance(features, (str, bytes, np.ndarray)) or not isinstance(features, Sequence):
        raise TypeError(f"`{name}` must be a sequence of (n_i, f) arrays, got "
                        f"{type(features).__name__}")
    if len(features) == 0:
        raise ValueError(f"`{name}` must hold at least one graph's features, got none")
    out = [check_array(F, f"{name}[{g}]", ndim=2) for g, F in enumerate(features)]
    f = out[0].shape[1]
    for g, F in enumerate(out):
        if F.shape[1] != f:
            raise ValueError(f"`{name}[{g}]` must have {f} columns like `{name}[0]`, got shape "
                             f"{F.shape}")
        if F.shape[0] == 0:
            raise ValueError(f"`{name}[{g}]` must describe at least one node, got shape "
                             f"{F.shape}")
    return out
