"""``transync datasets``: where the real data sets are found, and what they hold."""

from __future__ import annotations

from pathlib import Path

__all__ = ["add_parser"]


def _cmd_datasets(args) -> int:
    from ..datasets import data_home

    home = data_home(required=False)      # a TRANSYNC_DATA that points nowhere is an error
    if home is None:
        print("no data folder found: set TRANSYNC_DATA, or place the data in ../shared/data "
              "or the per-user cache folder (see `data_home`)")
        return 1
    print(f"data home: {home}")
    for sub in sorted(p for p in Path(home).iterdir() if p.is_dir()):
        n = sum(1 for _ in sub.rglob("*") if _.is_file())
        print(f"  {sub.name:14s} {n} files")
    return 0


def add_parser(sub) -> None:
    """Register ``datasets``."""
    p = sub.add_parser("datasets", help="show where the real data sets are found")
    p.set_defaults(func=_cmd_datasets)
