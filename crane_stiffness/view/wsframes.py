"""WebSocket frames (RFC 6455) and an HTTP request's head, as the live view's front (``view/front.py``) reads and
makes them: a frame is FIN and an opcode, a 7, 16 or 64-bit payload length, a 4-byte mask on a client's frame, the
payload. Pure functions over bytes."""
from __future__ import annotations

import struct


def frame(opcode: int, payload: bytes) -> bytes:
    """One unmasked frame with FIN set (the server's side)."""
    n = len(payload)
    if n < 126:
        head = struct.pack('!BB', 0x80 | opcode, n)
    elif n < 1 << 16:
        head = struct.pack('!BBH', 0x80 | opcode, 126, n)
    else:
        head = struct.pack('!BBQ', 0x80 | opcode, 127, n)
    return head + payload


def frame_bounds(buf: bytes | bytearray, pos: int) -> tuple[int, int, int, bool, bytes] | None:
    """The frame at ``pos`` of ``buf``: (opcode, payload start, end, FIN, mask: 4 bytes or empty), or None while it
    is incomplete."""
    if len(buf) - pos < 2:
        return None
    b0, b1 = buf[pos], buf[pos + 1]
    length, start = b1 & 0x7F, pos + 2
    if length == 126:
        if len(buf) - pos < 4:
            return None
        length, start = int.from_bytes(buf[pos + 2:pos + 4], 'big'), pos + 4
    elif length == 127:
        if len(buf) - pos < 10:
            return None
        length, start = int.from_bytes(buf[pos + 2:pos + 10], 'big'), pos + 10
    mask = b''
    if b1 & 0x80:
        if len(buf) - start < 4:
            return None
        mask, start = bytes(buf[start:start + 4]), start + 4
    if len(buf) < start + length:
        return None
    return b0 & 0x0F, start, start + length, bool(b0 & 0x80), mask


def announced_length(buf: bytes | bytearray, pos: int) -> int | None:
    """The payload length the frame at ``pos`` announces, once its header's length bytes are there."""
    if len(buf) - pos < 2:
        return None
    length = buf[pos + 1] & 0x7F
    if length == 126:
        return int.from_bytes(buf[pos + 2:pos + 4], 'big') if len(buf) - pos >= 4 else None
    if length == 127:
        return int.from_bytes(buf[pos + 2:pos + 10], 'big') if len(buf) - pos >= 10 else None
    return length


def unmask(data: bytes | bytearray, mask: bytes) -> bytes:
    """A client frame's payload unmasked (XOR with the 4-byte mask, repeated)."""
    n = len(data)
    key = (mask * (n // 4 + 1))[:n]
    return (int.from_bytes(data, 'little') ^ int.from_bytes(key, 'little')).to_bytes(n, 'little')


def parse_head(head: bytes) -> tuple[str, str, dict[str, list[str]]]:
    """An HTTP request's head: (method, path, header name in lower case -> values); ValueError if malformed."""
    lines = head.decode('latin-1').split('\r\n')
    parts = lines[0].split(' ')
    if len(parts) != 3 or not parts[2].startswith('HTTP/1.'):
        raise ValueError(f'not an HTTP/1.x request line: {lines[0][:80]!r}')
    headers: dict[str, list[str]] = {}
    for line in lines[1:]:
        if not line:
            continue
        name, sep, value = line.partition(':')
        if not sep or not name or name != name.strip():
            raise ValueError(f'malformed header line {line[:80]!r}')
        headers.setdefault(name.lower(), []).append(value.strip())
    return parts[0], parts[1], headers
