"""The one progress bar of the library (private): tqdm, or a silent stand-in when disabled."""

from __future__ import annotations


class _NoBar:
    """What a disabled bar offers: ``update``, ``close``, a context manager (tqdm not loaded)."""

    def update(self, n: int = 1) -> None:
        pass

    def set_postfix_str(self, s: str = "", refresh: bool = True) -> None:
        pass

    def close(self) -> None:
        pass

    def __enter__(self):
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def progress_bar(total: int, desc: str, *, enabled: bool = True, unit: str = "it",
                 leave: bool = True):
    """A tqdm bar over ``total`` steps, or a no-op object when ``enabled`` is false."""
    if not enabled or total == 0:
        return _NoBar()
    from tqdm.auto import tqdm

    return tqdm(total=total, desc=str(desc), unit=unit, dynamic_ncols=True, leave=leave)
