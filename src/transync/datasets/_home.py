"""Where the real data sets live.

Resolution order (the first that exists wins):

1. the environment variable ``TRANSYNC_DATA`` -- when set it must name an existing folder
   (a variable that points nowhere is an error, never a silent fallback; set to the empty
   string it counts as unset, the shell convention, and the "not found" message says so);
2. ``../shared/data`` relative to the current working directory, then relative to the source
   checkout this package runs from (only when it runs from a checkout, not an installed copy);
3. the per-user cache folder: ``$XDG_CACHE_HOME/transync``, default ``~/.cache/transync``
   (``%LOCALAPPDATA%\\transync`` on Windows).
"""

from __future__ import annotations

import os
from pathlib import Path

from .._validation import check_bool, check_path

__all__ = ["data_home"]

_PACKAGE_ROOT = Path(__file__).resolve().parents[3]


def no_folder(path: Path) -> str:
    """Why ``path`` is not a folder, for a message: ``"no such folder"`` or ``"a file, not a
    folder"``."""
    return "a file, not a folder" if path.exists() else "no such folder"


def _checkout_root() -> Path | None:
    """The repository root when this package runs from a source checkout (``src/`` layout)."""
    root = _PACKAGE_ROOT
    if (root / "pyproject.toml").is_file() and (root / "src" / "transync").is_dir():
        return root
    return None


def _cache_home() -> Path:
    if os.name == "nt" and os.environ.get("LOCALAPPDATA"):  # pragma: no cover - Windows
        return Path(os.environ["LOCALAPPDATA"]) / "transync"
    xdg = os.environ.get("XDG_CACHE_HOME")
    base = Path(xdg).expanduser() if xdg and Path(xdg).is_absolute() else Path.home() / ".cache"
    return base / "transync"


def _candidates() -> list[Path]:
    """The fallback folders, in order (``TRANSYNC_DATA`` excluded)."""
    try:
        out = [Path.cwd() / ".." / "shared" / "data"]
    except OSError:              # the working directory was removed
        out = []
    root = _checkout_root()
    if root is not None:
        out.append(root / ".." / "shared" / "data")
    out.append(_cache_home())
    seen, unique = set(), []
    for c in out:
        c = c.resolve()
        if c not in seen:
            seen.add(c)
            unique.append(c)
    return unique


def data_home(required: bool = True, *, subfolder: str | None = None) -> Path | None:
    """The folder of real data sets (never copied into the repository).

    Looks at the environment variable ``TRANSYNC_DATA`` first; when it is not set, at
    ``../shared/data`` relative to the working directory and to the source checkout, then at
    the per-user cache folder (``$XDG_CACHE_HOME/transync``, default ``~/.cache/transync``).

    Parameters
    ----------
    required : bool, default=True
        Raise ``FileNotFoundError`` naming every place looked at when no folder is found
        (otherwise return ``None``).
    subfolder : str, default=None
        Return this folder inside the data home instead (it must exist when ``required``).

    Returns
    -------
    pathlib.Path or None
        The data home (or its ``subfolder``); ``None`` when none is found and ``required``
        is false.

    Raises
    ------
    FileNotFoundError, NotADirectoryError
        ``TRANSYNC_DATA`` is set but names no folder (whatever ``required``), or nothing was
        found and ``required`` is true.
    ValueError, TypeError
        ``TRANSYNC_DATA`` naming an unknown ``~user``, ``required`` not a bool, ``subfolder``
        not a folder name inside the data home (absolute, or with ``..``).

    Examples
    --------
    >>> home = data_home(required=False)
    >>> home is None or home.is_dir()
    True
    """
    check_bool(required, "required")
    if subfolder is not None:
        if not isinstance(subfolder, str) or not subfolder:
            raise TypeError(f"`subfolder` must be None or a folder name (non-empty str), got "
                            f"{type(subfolder).__name__} {subfolder!r:.40}")
        if Path(subfolder).is_absolute() or ".." in Path(subfolder).parts:
            raise ValueError(f"`subfolder` must be a folder inside the data home, got "
                             f"{subfolder!r:.80}")
    env = os.environ.get("TRANSYNC_DATA")
    if env:                     # empty counts as unset (as XDG_CACHE_HOME does), said below
        home = check_path(env, "TRANSYNC_DATA")
        if not home.exists():
            raise FileNotFoundError(f"TRANSYNC_DATA={env!r} does not exist; set it to the folder "
                                    "holding the real data sets, or unset it")
        if not home.is_dir():
            raise NotADirectoryError(f"TRANSYNC_DATA={env!r} is not a folder; set it to the "
                                     "folder holding the real data sets, or unset it")
        looked = [home]
    else:
        looked = _candidates()
        home = next((c for c in looked if c.is_dir()), None)
    if home is not None and subfolder is not None:
        home = home / subfolder
        if not home.is_dir():
            looked, home = [home], None
    if home is None and required:
        what = f"the data folder{'' if subfolder is None else f' {subfolder!r}'}"
        where = ", ".join(str(p) for p in looked)
        raise FileNotFoundError(f"cannot find {what}: looked at {where}"
                                + ("" if env else " (TRANSYNC_DATA not set)" if env is None
                                   else " (TRANSYNC_DATA is empty: taken as not set)")
                                + "; set TRANSYNC_DATA to the folder holding the real data sets")
    return home
