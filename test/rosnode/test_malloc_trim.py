"""crane_stiffness.rosnode.malloc_trim: the freed pages of a long-running node go back to the system (glibc's
malloc_trim). No ROS: blocks malloc'd and freed directly, the resident set read from /proc."""
from __future__ import annotations

import ctypes
import ctypes.util

from crane_stiffness.rosnode.malloc_trim import release_free_memory, trim_available


def _rss_bytes() -> int:
    with open('/proc/self/statm') as f:
        return int(f.read().split()[1]) * 4096


def test_freed_blocks_go_back_to_the_system() -> None:
    assert trim_available(), 'this machine runs glibc: malloc_trim must be found'
    libc = ctypes.CDLL(ctypes.util.find_library('c') or 'libc.so.6')
    libc.malloc.restype = ctypes.c_void_p
    libc.malloc.argtypes = [ctypes.c_size_t]
    libc.free.argtypes = [ctypes.c_void_p]
    # 64 MB of 1 KB blocks, written so their pages are resident; all freed but the last, which pins the top of the
    # heap: free() alone cannot shrink it, the pages stay with the process.
    blocks = [libc.malloc(1024) for _ in range(64 * 1024)]
    for b in blocks:
        ctypes.memset(b, 1, 1024)
    for b in blocks[:-1]:
        libc.free(b)
    before = _rss_bytes()
    assert release_free_memory() is True
    after = _rss_bytes()
    libc.free(blocks[-1])
    assert before - after > 32 * 1024 * 1024, f'RSS {before / 1e6:.1f} MB -> {after / 1e6:.1f} MB'
