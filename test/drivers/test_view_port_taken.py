"""A device emulator's web page on the live view's page port (docs once showed ``http_port:=8080``, the view's
default): the view stops naming the port, the parameter and the launch argument that choose it, not with a bare
"Address already in use"."""
from __future__ import annotations

import socket

import pytest
from rclpy.parameter import Parameter

from crane_stiffness.nodes.live_view import LiveViewNode
from crane_stiffness.view.errors import ViewError

pytestmark = pytest.mark.ros


@pytest.mark.parametrize('parameter, argument', [('http_port', 'view_http_port'), ('port', 'view_port')])
def test_a_taken_port_is_named_with_what_chooses_it(rclpy_context, parameter, argument):
    with socket.socket() as taken:
        taken.bind(('127.0.0.1', 0))
        taken.listen()
        port = taken.getsockname()[1]
        other = 'port' if parameter == 'http_port' else 'http_port'
        with pytest.raises(ViewError) as info:
            LiveViewNode(context=rclpy_context, parameter_overrides=[
                Parameter(parameter, value=port), Parameter(other, value=0)])
    message = str(info.value)
    assert f'127.0.0.1:{port}' in message and 'already in use' in message.lower(), message
    assert f'(parameter {parameter}; ros2 launch: {argument}:=...)' in message, message
