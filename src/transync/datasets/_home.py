"""Where the real data sets live: ``$TRANSYNC_DATA``, else ``../shared/data`` beside the repository."""

from __future__ import annotations

import os
from pathlib import Path

__all__ = ["data_home"]

_REPO_ROOT = Path(__file__).resolve().parents[3]


def _default_home() -> Path:
    return (_REPO_ROOT / ".." / "shared" / "data").resolve()


def data_home(required: bool = True, *, subfolder: str | None = None) -> Path | None:
    """The folder of real data sets (never copied into the repository).

    Looks at the environment variable ``TRANSYNC_DATA`` first, then at ``../shared/data`` next to
    the repository root.

    Parameters
    ----------
    required : bool, default=True
        Raise ``FileNotFoundError`` naming both places when no folder is found (otherwise return
        ``None``).
    subfolder : str, default=None
        Return this folder inside the data home instead (it must exist when ``required``).

    Returns
    -------
    pathlib.Path or None

    Examples
    --------
    >>> home = data_home(required=False)
    >>> home is None or home.is_dir()
    True
    """
    env = os.environ.get("TRANSYNC_DATA")
    candidates = [Path(env).expanduser()] if env else []
    candidates.append(_default_home())
    home = next((c for c in candidates if c.is_dir()), None)
    if home is not None and subfolder is not None:
        home = home / subfolder
        if not home.is_dir():
            home = None
    if home is None and required:
        where = f"TRANSYNC_DATA={env!r}" if env else "TRANSYNC_DATA (not set)"
        what = f"the data folder{'' if subfolder is None else f' {subfolder!r}'}"
        raise FileNotFoundError(f"cannot find {what}: looked at {where} and at "
                                f"{_default_home()}; set TRANSYNC_DATA to the folder holding "
                                "the real data sets")
    return home
