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
    subs = {p.name: p for p in Path(home).iterdir() if p.is_dir()}
    for name, (what, readers) in KNOWN.items():
        if name not in subs:
            print(f"  {name:14s} missing ({what}; give {readers} a folder instead)")
            continue
        n = sum(1 for _ in subs[name].rglob("*") if _.is_file())
        extra = ""
        if name == "tu":
            sets = [p.name for p in sorted(subs[name].iterdir()) if p.is_dir()]
            extra = (f"; sets: {', '.join(sets[:12])}{' ...' if len(sets) > 12 else ''}"
                     if sets else "; no set folders in it")
        print(f"  {name:14s} {n} files ({what}, read by {readers}{extra})")
    other = sorted(set(subs) - set(KNOWN))
    if other:
        print(f"  other folders, not read by name: {', '.join(other[:12])}"
              f"{' ...' if len(other) > 12 else ''}")
    return 0


#: the folders transync reads by name from the data home, and what reads them
KNOWN = {
    "cmu-house": ("CMU landmark sequence",
                  "load_cmu_sequence and the cmu / subgraph experiments"),
    "tu": ("TU graph sets", "load_tu, transync kernel and the kernels experiment"),
    "oxford-graf": ("Oxford graf images and ground truth", "load_graf"),
    "adelaidermf": ("AdelaideRMF pairs", "load_adelaidermf and list_adelaidermf"),
}


def add_parser(sub) -> None:
    """Register ``datasets``."""
    p = sub.add_parser("datasets", help="show where the real data sets are found")
    p.set_defaults(func=_cmd_datasets)
