"""Free ports for the live view, the device emulators and the drivers in the demo, tests and benchmarks: the
preferred one if it is free on 127.0.0.1, else one the kernel picks (other programs on the machine may hold the
defaults)."""
from __future__ import annotations

import socket


def free_port(preferred: int = 0, host: str = '127.0.0.1', *, kind: int = socket.SOCK_STREAM) -> int:
    """``preferred`` if nothing uses it now on ``host``, else a free port (there is a small race until it is bound).
    ``kind``: SOCK_STREAM (TCP) or SOCK_DGRAM (UDP)."""
    for port in ((preferred, 0) if preferred else (0,)):
        with socket.socket(socket.AF_INET, kind) as s:
            try:
                s.bind((host, port))
            except OSError:
                continue
            return int(s.getsockname()[1])
    raise OSError('no free port')
