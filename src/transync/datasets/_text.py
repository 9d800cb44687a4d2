"""Reading numbers from the text formats: one rule for what a number is (CMU label files,
Oxford/HPatches ground truth, TU node attributes) and what a line is (CMU, Oxford/HPatches).

A number is an ASCII decimal literal (``-1.5``, ``.5``, ``3e-2``): Python's ``float`` would also
take ``1_5`` (as 15), full-width digits, and surrounding NUL bytes, which in a data file are
damage, not numbers. A line ends at ``\\n``, ``\\r\\n`` or ``\\r`` only (``str.splitlines``
also breaks at form feeds, ``\\x1c``-``\\x1e``, ``\\x85`` and ``\\u2028``, which shifts the
line numbers the messages give and can split one row into two). TU files are scanned as bytes
(``transync.datasets._tu``) after :func:`unix_newlines`, with the same lines.
"""

from __future__ import annotations

import re

__all__ = ["NUMBER_BYTES", "is_number", "text_lines", "unix_newlines"]

_NUMBER = re.compile(r"[+-]?(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?", re.ASCII)
_LINE_BREAK = re.compile(r"\r\n|\r|\n")

#: The bytes a number may contain (a vectorized pre-check for large files).
NUMBER_BYTES = b"0123456789+-.eE"


def is_number(token: str) -> bool:
    """Whether ``token`` is an ASCII decimal literal (finite by construction, except overflow).

    >>> [is_number(t) for t in ("-1.5", ".5", "3e-2", "1_5", "nan", "2\\x00")]
    [True, True, True, False, False, False]
    """
    return _NUMBER.fullmatch(token) is not None


def text_lines(text: str) -> list[str]:
    """``text`` split at ``\\n``, ``\\r\\n`` and ``\\r`` only; line ``k`` (1-based) is item
    ``k - 1`` as an editor numbers it.

    >>> text_lines("1 2\\x0c3 4\\r\\n5 6")
    ['1 2\\x0c3 4', '5 6']
    """
    return _LINE_BREAK.split(text)


def unix_newlines(data: bytes) -> bytes:
    """``data`` with every ``\\r\\n`` and lone ``\\r`` turned into ``\\n``: the lines of
    :func:`text_lines`, for scanners that split at ``\\n`` only.

    >>> unix_newlines(b"1 2\\r3 4\\r\\n5 6\\n")
    b'1 2\\n3 4\\n5 6\\n'
    """
    if b"\r" not in data:
        return data
    return data.replace(b"\r\n", b"\n").replace(b"\r", b"\n")
