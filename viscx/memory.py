"""Freed memory given back to the operating system between the large stages of a build.

numpy's arrays below glibc's mmap threshold (which grows up to 32 MiB as large arrays
are freed) live in the heap arenas of the threads that made them; freed, their pages
stay with the process. A stage that frees its pieces before the next one allocates
then keeps its resident size high for nothing: V1 at 997 polygons peaked at 1.74 GB
resident with 0.9 GB of live arrays, 1.38 GB when the heap is trimmed between phases
(the same time).
"""

import ctypes
import ctypes.util

_LIBC = None


def _libc():
    global _LIBC
    if _LIBC is None:
        name = ctypes.util.find_library("c")
        try:
            _LIBC = ctypes.CDLL(name) if name else False
        except OSError:
            _LIBC = False
    return _LIBC


def release_free_memory():
    """Give the heap's free pages back to the system (glibc's ``malloc_trim``; nothing
    where the C library has none)."""
    libc = _libc()
    if libc and hasattr(libc, "malloc_trim"):
        libc.malloc_trim(0)


def memory_budget():
    """Bytes one input may make viscx allocate at once (a declared array, an image, a
    header's counts): ``VISCX_MEMORY_BUDGET`` (bytes) when set, else half the machine's
    memory. Inputs that need more are refused before anything is allocated."""
    import os

    value = os.environ.get("VISCX_MEMORY_BUDGET")
    if value:
        try:
            return int(float(value))
        except ValueError:
            pass
    try:
        return os.sysconf("SC_PHYS_PAGES") * os.sysconf("SC_PAGE_SIZE") // 2
    except (ValueError, OSError):
        return 4 << 30
