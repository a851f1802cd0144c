"""Who may use the live view: the one place its servers (the page's HTTP server and the WebSocket front) ask.

Three checks, as Jupyter's server makes them:

- **Host** (against DNS rebinding: a foreign name made to resolve to this machine): a request's ``Host`` header must
  name the server by an address it listens on (the bound address; with 0.0.0.0 or ``::`` any address of this
  machine's interfaces), ``localhost``, this machine's host name, or a name of ``allowed_hosts``.
- **Origin** (against cross-site use: any web page the operator opens can open a WebSocket to any address): a
  request that carries ``Origin`` (every browser's does) must come from the page itself (``http://<an allowed host>:
  <the page's port>``) or from an origin of ``allowed_origins`` (e.g. ``https://app.foxglove.dev``). A request without
  ``Origin`` is not a browser's and passes (it still needs the token where the token is needed).
- **Token**: a secret made at start (:func:`new_token`) or given. Every service call needs it; when the server listens
  on an address other than loopback, connecting at all needs it. A client presents it as ``?token=...`` in the URL it
  connects to (what a browser's WebSocket and the Foxglove and Lichtblick apps can send) or as the HTTP header
  ``Authorization: Bearer ...`` (tools).

Pure: no ROS, no network I/O but reading this machine's interface addresses.
"""
from __future__ import annotations

import array
import fcntl
import hmac
import ipaddress
import os
import secrets
import socket
import struct
from dataclasses import dataclass, field
from pathlib import Path
from urllib.parse import parse_qs, urlsplit

from crane_stiffness.view.errors import ViewError

#: Bytes of randomness in a made token (43 URL-safe characters).
TOKEN_BYTES = 32
_SIOCGIFADDR = 0x8915  # Linux ioctl: an interface's IPv4 address


def new_token() -> str:
    """A fresh secret, URL-safe (``secrets.token_urlsafe``)."""
    return secrets.token_urlsafe(TOKEN_BYTES)


def is_loopback(host: str) -> bool:
    """Whether binding ``host`` keeps a server on this machine (127.0.0.0/8, ::1, ``localhost``)."""
    if host == 'localhost':
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False


def is_wildcard(host: str) -> bool:
    """Whether binding ``host`` listens on every interface."""
    return host in ('', '0.0.0.0', '::')


def interface_addresses() -> set[str]:
    """The IP addresses of this machine's interfaces (IPv4 by ioctl, IPv6 from /proc; Linux), loopback included."""
    found = {'127.0.0.1', '::1'}
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sock:
        for _index, name in socket.if_nameindex():
            request = array.array('B', struct.pack('256s', name.encode()[:15]))
            try:
                fcntl.ioctl(sock.fileno(), _SIOCGIFADDR, request)
            except OSError:  # an interface without an IPv4 address
                continue
            found.add(socket.inet_ntoa(request.tobytes()[20:24]))
    try:
        lines = Path('/proc/net/if_inet6').read_text().splitlines()
    except OSError:
        lines = []
    for line in lines:
        raw = line.split()[0]
        found.add(str(ipaddress.IPv6Address(bytes.fromhex(raw))))
    return found


def _split_host(value: str) -> tuple[str, int | None]:
    """A Host header or netloc as (host in lower case without brackets, port or None); ViewError if malformed."""
    try:
        parts = urlsplit('//' + value)
        host, port = parts.hostname, parts.port
    except ValueError as exc:
        raise ViewError(f'Host {value!r}: {exc}') from exc
    if not host:
        raise ViewError(f'Host {value!r}: names no host')
    return host.lower(), port


def _names(text: str, field_name: str, origin: bool) -> tuple[str, ...]:
    """The comma-separated entries of a parameter; an origin must be ``scheme://host[:port]``."""
    out = []
    for entry in (e.strip() for e in text.split(',')):
        if not entry:
            continue
        if origin:
            parts = urlsplit(entry)
            if parts.scheme not in ('http', 'https') or not parts.hostname or parts.path not in ('', '/') \
                    or parts.query:
                raise ViewError(f'{field_name} = {entry!r}: must be an origin, scheme://host[:port] (http or '
                                f'https, no path), e.g. https://app.foxglove.dev')
            entry = entry.rstrip('/').lower()
        elif not entry.replace('-', '').replace('.', '').replace(':', '').isalnum():
            raise ViewError(f'{field_name} = {entry!r}: must be a host name or address')
        out.append(entry.lower())
    return tuple(out)


@dataclass
class AccessPolicy:
    """What the two servers accept. ``bind``: the address both listen on; ``page_port``: the page's port (its
    origin is allowed); ``token``: the secret (empty: a new one); ``allowed_origins``, ``allowed_hosts``: comma-
    separated extra origins and host names (the node's parameters)."""

    bind: str
    page_port: int = 0
    token: str = ''
    allowed_origins: str = ''
    allowed_hosts: str = ''
    hosts: frozenset[str] = field(init=False)
    origins: frozenset[str] = field(init=False)

    def __post_init__(self) -> None:
        if not self.token:
            self.token = new_token()
        elif len(self.token) < 16 or not self.token.isprintable() or ' ' in self.token:
            raise ViewError('token = (hidden): must be at least 16 printable characters without spaces (empty: '
                            'a new random one)')
        # the host name only: its fully qualified form would need a DNS lookup (seconds where DNS is down); a lab's
        # DNS name goes in allowed_hosts
        names = {'localhost', socket.gethostname().lower()}
        if is_wildcard(self.bind):
            names |= interface_addresses()
        else:
            names |= {self.bind.lower().strip('[]')}
            if is_loopback(self.bind):
                names |= {'127.0.0.1', '::1'}
        names |= set(_names(self.allowed_hosts, 'allowed_hosts', origin=False))
        self.hosts = frozenset(names)
        self.origins = frozenset(_names(self.allowed_origins, 'allowed_origins', origin=True))

    @property
    def open_to_read(self) -> bool:
        """Whether a client without the token may connect (and only watch): on a loopback address only."""
        return is_loopback(self.bind)

    def host_refusal(self, host_header: str | None) -> str | None:
        """Why a request's ``Host`` header is refused (None: accepted). A request without one (HTTP/1.0) is
        refused too: the check could not be made."""
        if not host_header:
            return 'no Host header'
        try:
            host, _port = _split_host(host_header)
        except ViewError as exc:
            return str(exc)
        if host not in self.hosts:
            return f'Host {host_header!r} is not a name or address this server listens on'
        return None

    def origin_refusal(self, origin: str | None) -> str | None:
        """Why a request's ``Origin`` header is refused (None: accepted): not the page's own origin nor one of
        ``allowed_origins``. No ``Origin`` (not a browser) passes."""
        if origin is None:
            return None
        origin = origin.strip().lower().rstrip('/')
        if origin in self.origins:
            return None
        parts = urlsplit(origin)
        try:
            port = parts.port or (443 if parts.scheme == 'https' else 80)
        except ValueError:
            return f'Origin {origin!r} is malformed'
        if parts.scheme == 'http' and (parts.hostname or '') in self.hosts and port == self.page_port:
            return None
        return f'Origin {origin!r} is neither the page\'s own nor in allowed_origins'

    def token_ok(self, presented: str | None) -> bool:
        """Whether ``presented`` is the token (compared in constant time)."""
        return presented is not None and hmac.compare_digest(presented.encode(), self.token.encode())

    def presented_token(self, path: str, authorization: str | None) -> str | None:
        """The token a request presents: ``?token=`` of its path, else ``Authorization: Bearer ...``."""
        values = parse_qs(urlsplit(path).query).get('token')
        if values:
            return values[0]
        if authorization and authorization.lower().startswith('bearer '):
            return authorization[7:].strip()
        return None

    def page_url(self, host: str, port: int) -> str:
        """The page's address with the token, as the operator opens it (Jupyter prints its URL so)."""
        shown = f'[{host}]' if ':' in host else host
        return f'http://{shown}:{port}/?token={self.token}'


def default_token_file(ws_port: int) -> Path:
    """Where the token is written for tools when no file is named: ``$ROS_HOME`` (else ``~/.ros``)
    ``/crane_stiffness/live_view_<WebSocket port>.token``."""
    home = Path(os.environ.get('ROS_HOME') or Path.home() / '.ros')
    return home / 'crane_stiffness' / f'live_view_{ws_port}.token'


def write_token_file(path: Path, token: str) -> None:
    """Write ``token`` to ``path`` readable by its owner only (0600, made so before the secret is in it)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
    try:
        os.fchmod(fd, 0o600)  # an existing file keeps its mode through O_CREAT: made private here
        os.write(fd, (token + '\n').encode())
    finally:
        os.close(fd)
