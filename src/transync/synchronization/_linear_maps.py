"""Placeholder: synchronization of invertible linear maps (being written)."""


def synchronize_linear_maps(*args, **kwargs):  # pragma: no cover - replaced
    raise NotImplementedError


def synchronize_homographies(*args, **kwargs):  # pragma: no cover - replaced
    raise NotImplementedError


class LinearMapSyncResult:  # pragma: no cover - replaced
    pass
