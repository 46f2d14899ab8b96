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


# mallopt(3) parameters (glibc's malloc.h)
_M_TRIM_THRESHOLD, _M_TOP_PAD, _M_MMAP_THRESHOLD = -1, -2, -3
#: Allocations up to this size come from the heap (glibc's largest mmap threshold on 64 bits).
MMAP_THRESHOLD = 32 << 20
#: Free memory kept at the heap's top before glibc gives it back on its own, and the extra
#: asked of the system each time the heap grows.
TRIM_THRESHOLD = 512 << 20
TOP_PAD = 64 << 20


def keep_freed_memory():
    """Let the heap keep and reuse freed memory between the builders' steps instead of
    returning it to the system at once (glibc's ``mallopt``; nothing where the C library
    has none). By default glibc maps every array above a threshold on its own and unmaps
    it when freed, and trims the heap's top above twice that threshold: the next array of
    that size faults its pages in again, zeroed by the kernel, in system time. Builds
    allocate and free arrays of a few MB by the thousand (office(300): 485,000 page faults
    and 2.06 system CPU s; with these settings 256,000 and 1.47 s, the peak resident size
    0.75 -> 0.77 GB). :func:`release_free_memory` still trims the heap between stages.

    Returns
    -------
    bool
        Whether the settings were taken.
    """
    libc = _libc()
    if not (libc and hasattr(libc, "mallopt")):
        return False
    return all(libc.mallopt(param, value) == 1 for param, value in (
        (_M_MMAP_THRESHOLD, MMAP_THRESHOLD), (_M_TRIM_THRESHOLD, TRIM_THRESHOLD), (_M_TOP_PAD, TOP_PAD)))


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
