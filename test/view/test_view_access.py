"""The live view's access policy (crane_stiffness.view.access) without a server: which Host and Origin headers it
refuses, the token's comparison and where a client may present it, the parameters' rules, and the token file's
mode."""
from __future__ import annotations

import os
import socket
import stat

import pytest

from crane_stiffness.view.access import (AccessPolicy, default_token_file, interface_addresses, is_loopback,
                                         new_token, write_token_file)
from crane_stiffness.view.errors import ViewError


def test_host_header_must_name_the_server():
    policy = AccessPolicy('127.0.0.1', page_port=8080)
    for good in ('127.0.0.1:8080', '127.0.0.1', 'localhost:8765', 'LOCALHOST:8765', '[::1]:8080',
                 f'{socket.gethostname()}:8080'):
        assert policy.host_refusal(good) is None, good
    # DNS rebinding: a name of the attacker's made to resolve to 127.0.0.1; an address the server is not on
    for bad in ('evil.example:8080', 'evil.example', '10.1.2.3:8080', '127.0.0.1.evil.example'):
        assert 'is not a name or address this server listens on' in policy.host_refusal(bad), bad
    assert policy.host_refusal(None) == 'no Host header'
    assert policy.host_refusal('') == 'no Host header'
    assert 'Host' in policy.host_refusal('127.0.0.1:notaport')
    # a lab's DNS name of the rig PC, allowed by the parameter
    lab = AccessPolicy('127.0.0.1', allowed_hosts='rig-pc.lab.example, other')
    assert lab.host_refusal('rig-pc.lab.example:8080') is None and lab.host_refusal('other') is None


def test_every_interface_address_is_a_host_on_the_wildcard():
    addresses = interface_addresses()
    assert {'127.0.0.1', '::1'} <= addresses
    policy = AccessPolicy('0.0.0.0', page_port=8080)
    for address in addresses:
        host = f'[{address}]' if ':' in address else address
        assert policy.host_refusal(f'{host}:8080') is None, address
    assert policy.host_refusal('evil.example:8080') is not None
    assert not policy.open_to_read  # off loopback: connecting needs the token
    assert AccessPolicy('127.0.0.1').open_to_read and AccessPolicy('::1').open_to_read


def test_origin_must_be_the_pages_own_or_allowed():
    policy = AccessPolicy('127.0.0.1', page_port=8080, allowed_origins='https://app.foxglove.dev, '
                                                                      'http://127.0.0.1:5173/')
    for good in (None, 'http://127.0.0.1:8080', 'http://localhost:8080', 'http://[::1]:8080',
                 'https://app.foxglove.dev', 'HTTPS://APP.FOXGLOVE.DEV/', 'http://127.0.0.1:5173'):
        assert policy.origin_refusal(good) is None, good
    for bad in ('http://evil.example', 'http://127.0.0.1:8081', 'https://127.0.0.1:8080', 'null',
                'http://evil.example:8080', 'https://app.foxglove.dev.evil.example', 'http://app.foxglove.dev'):
        assert "is neither the page's own nor in allowed_origins" in policy.origin_refusal(bad), bad


@pytest.mark.parametrize('origins', ['app.foxglove.dev', 'ftp://x.example', 'https://x.example/path',
                                     'https://x.example/?q=1'])
def test_allowed_origins_must_be_origins(origins):
    with pytest.raises(ViewError, match=r"allowed_origins = '.*': must be an origin, scheme://host\[:port\]"):
        AccessPolicy('127.0.0.1', allowed_origins=origins)


def test_allowed_hosts_must_be_names():
    with pytest.raises(ViewError, match=r"allowed_hosts = 'a/b': must be a host name or address"):
        AccessPolicy('127.0.0.1', allowed_hosts='good, a/b')


def test_the_token_made_given_compared_and_presented():
    made = AccessPolicy('127.0.0.1')
    assert len(made.token) >= 40 and made.token != AccessPolicy('127.0.0.1').token
    assert new_token() != new_token()
    given = AccessPolicy('127.0.0.1', token='a-lab-secret-0123456789')
    assert given.token_ok('a-lab-secret-0123456789')
    assert not given.token_ok('a-lab-secret-012345678') and not given.token_ok(None) and not given.token_ok('')
    assert given.presented_token('/?token=abc', None) == 'abc'
    assert given.presented_token('/?x=1&token=a%2Bb', None) == 'a+b'
    assert given.presented_token('/', 'Bearer xyz') == 'xyz'
    assert given.presented_token('/?token=abc', 'Bearer xyz') == 'abc'
    assert given.presented_token('/', 'Basic xyz') is None and given.presented_token('/', None) is None
    assert given.page_url('127.0.0.1', 8080) == 'http://127.0.0.1:8080/?token=a-lab-secret-0123456789'
    assert given.page_url('::1', 8080) == 'http://[::1]:8080/?token=a-lab-secret-0123456789'
    for bad in ('short', 'has a space in it, long enough'):
        with pytest.raises(ViewError, match='token = \\(hidden\\): must be at least 16 printable characters'):
            AccessPolicy('127.0.0.1', token=bad)


def test_the_token_file_is_its_owners_only(tmp_path, monkeypatch):
    path = tmp_path / 'sub' / 'token'
    path.parent.mkdir()
    path.write_text('old')
    os.chmod(path, 0o644)  # an existing file readable by others: made private before the secret goes in
    write_token_file(path, 'the-secret')
    assert path.read_text() == 'the-secret\n'
    assert stat.S_IMODE(path.stat().st_mode) == 0o600
    monkeypatch.setenv('ROS_HOME', str(tmp_path / 'roshome'))
    assert default_token_file(8765) == tmp_path / 'roshome' / 'crane_stiffness' / 'live_view_8765.token'
    write_token_file(default_token_file(8765), 'x')
    assert stat.S_IMODE(default_token_file(8765).stat().st_mode) == 0o600


def test_loopback_addresses():
    assert is_loopback('127.0.0.1') and is_loopback('127.3.2.1') and is_loopback('::1') and is_loopback('localhost')
    assert not is_loopback('0.0.0.0') and not is_loopback('192.168.1.5') and not is_loopback('rig-pc')
