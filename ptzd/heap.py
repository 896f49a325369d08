"""The process heap as glibc's malloc sees it, and handing its free pages back to the kernel.

Why the daemon trims: its frame-, box- and particle-sized numpy and OpenCV temporaries change
size with the zoom and the target, and are allocated from several threads (the vision
worker, FFmpeg's and OpenCV's own). glibc keeps what they free in its arenas, in pieces
between live blocks, for reuse; over minutes that free part grew from 9 to 22 MB in a
12-minute soak while the live part went up and came back. `malloc_trim(0)` returns the
whole free pages of every arena (madvise), so RSS follows what is live. It took about 2 ms
to give back 70 MB here, so the daemon calls it every `TRIM_INTERVAL_S` on its vision thread,
between frames.

Elsewhere than glibc (musl, macOS) both functions do nothing: `malloc_stats()` is empty and
`trim()` returns False.
"""

from __future__ import annotations

import ctypes
from collections.abc import Callable
from typing import cast

TRIM_INTERVAL_S = 30.0

_MB = 1024 * 1024


class _MallInfo2(ctypes.Structure):
    _fields_ = [(name, ctypes.c_size_t) for name in (
        "arena", "ordblks", "smblks", "hblks", "hblkhd", "usmblks", "fsmblks", "uordblks",
        "fordblks", "keepcost")]  # fmt: skip


def _libc_function(
    name: str, restype: type | None, *argtypes: type
) -> Callable[..., object] | None:
    try:
        function = getattr(ctypes.CDLL(None), name)
    except (OSError, AttributeError):  # not glibc, or an older one (mallinfo2: glibc 2.33)
        return None
    function.restype = restype
    function.argtypes = list(argtypes)
    return cast(Callable[..., object], function)


_mallinfo2 = _libc_function("mallinfo2", _MallInfo2)
_malloc_trim = _libc_function("malloc_trim", ctypes.c_int, ctypes.c_size_t)


def malloc_stats() -> dict[str, float]:
    """glibc malloc's own account of the heap (MB): `malloc_in_use_mb`, held by live blocks
    (those in its arenas plus those it mmapped); `malloc_free_mb`, free but kept in its
    arenas; `malloc_mmapped_mb`, the mmapped part of in use. Python's small objects live in
    its own arenas, outside malloc, so these are not all of RssAnon."""
    if _mallinfo2 is None:
        return {}
    info = cast(_MallInfo2, _mallinfo2())
    return {
        "malloc_in_use_mb": round((info.uordblks + info.hblkhd) / _MB, 2),
        "malloc_free_mb": round(info.fordblks / _MB, 2),
        "malloc_mmapped_mb": round(info.hblkhd / _MB, 2),
    }


def trim() -> bool:
    """Give malloc's free whole pages back to the kernel; True if any were."""
    if _malloc_trim is None:
        return False
    return bool(_malloc_trim(0))
