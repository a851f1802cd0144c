"""modbus_emulator: the simulated LVDT served as a Modbus TCP analog input (a thin adapter around
crane_stiffness.devices.modbus_device and sim.sensors.LvdtModel), so the real driver ``modbus_lvdt`` can read it.

Subscribes /crane/platform_pose (PoseStamped, crane_base), held from arrival on, like ``lvdt``. Serves Modbus TCP
on ``host:port`` (port 0 = a free port, logged and on /diagnostics): every read of the channel's registers is the
LVDT model's reading of the held pose (axis, contact point, noise, resolution, stroke: the ``lvdt`` parameters of
the same names), encoded as the channel parameters say (``register``, ``data_type``, ``word_order``, raw =
(metres − ``offset``) / ``gain``: the same parameters ``modbus_lvdt`` decodes with). Until the first pose arrives
every read answers "server device busy" (Modbus exception 6), as a DAQ channel still settling does, so the driver
publishes no reading of a pose nobody measured: a load program that waits for /lvdt/displacement then starts only
once the whole chain is live, and ``zero_on_first_pose`` zeroes the model at the unloaded pose (had the emulator
served the rest pose and met the crane's poses only during the first ramp, it zeroed under load: every reading
offset by the load at that instant, a stiffness several per cent off). True calibration errors and coloured noise
as ``lvdt`` has them (``truth.*``, ``noise.*``; ``truth.mode: drawn`` draws from its own ``calibration.*``), all off
by default.

Between sessions: an emulator that stays up (a lab's stand-in for the DAQ, started once) forgets the held pose and
its zero when the platform pose's last publisher leaves (the session's crane_model ended) and on ~/reset
(std_srvs/Trigger): every read answers "busy" again until the next session's first pose, which it zeroes on as a
fresh emulator would, so a new session never reads the previous one's platform.
"""
from __future__ import annotations

import time
from typing import Any

import numpy as np
from geometry_msgs.msg import PoseStamped
from rclpy.node import Node
from std_srvs.srv import Trigger

from crane_stiffness.contract import topics
from crane_stiffness.params.spec import ParamSpec
from crane_stiffness.devices.modbus_device import ModbusDevice
from crane_stiffness.drivers.errors import ParameterError
from crane_stiffness.rosnode.qos import RELIABLE_QOS
from crane_stiffness.rosnode.diagnostics import Diagnostics, InputLag, SensorCounters
from crane_stiffness.rosnode.messages import pose_vector
from crane_stiffness.rosnode.run import run
from crane_stiffness.rosnode.parameters import Params, check, positive
from crane_stiffness.rosnode.device_params import MAX_INPUT_LAG, check_address, check_start_only
from crane_stiffness.nodes.modbus_lvdt import CHANNEL_PARAMS, channel_from
from crane_stiffness.sim.calibration import LVDT_CALIBRATION_PARAMS
from crane_stiffness.sim.sensors import LVDT_IMPERFECTION_PARAMS, LVDT_PARAMS, LvdtModel, lvdt_from_params
from crane_stiffness.contract.status import OK, WARN

PARAMS = (
    ParamSpec('host', '127.0.0.1', 'address to serve Modbus TCP on (keep it on loopback or a test network '
              'namespace) [-]'),
    ParamSpec('port', 5020, 'TCP port; 0 = a free port (logged and on /diagnostics). 502, the Modbus port, needs '
              'root [-]', low=0, high=65535),
    *CHANNEL_PARAMS,
    MAX_INPUT_LAG,
    *LVDT_PARAMS,
    *LVDT_CALIBRATION_PARAMS,
    *LVDT_IMPERFECTION_PARAMS,
)
START_ONLY = ('host', 'port', 'unit_id')
#: How often a long-running emulator looks whether the session's model is still there [s].
SESSION_CHECK_S = 0.2


def _validate(values: dict[str, Any]):
    check_address(values, allow_zero=True)
    check(1 <= values['unit_id'] <= 247, 'unit_id', values['unit_id'], 'must be in 1..247')
    positive(values, 'max_input_lag_s')
    try:
        channel = channel_from(values)
    except ParameterError as exc:
        raise ValueError(str(exc)) from None
    return channel, lvdt_from_params(values)


class ModbusEmulator(Node):
    """Holds the platform pose; every Modbus read measures it with the LVDT model."""

    def __init__(self, **kwargs: Any) -> None:
        super().__init__('modbus_emulator', **kwargs)
        # received = poses = used + dropped_non_finite; published = register reads served
        self.counters = SensorCounters()
        self.pose: np.ndarray | None = None  # the held pose: u (3) then Q row-major (9)
        self.zero_pose: np.ndarray | None = None
        self.model: LvdtModel | None = None  # set by _apply (Params, below): the methods assert it
        self.device: ModbusDevice | None = None
        self.settings: dict[str, Any] = {}
        self.t0 = time.monotonic()  # the coloured noise's time origin (reads come on the wall clock)
        self.params = Params(self, PARAMS, self._validate, self._apply)
        self.lag = InputLag()
        self.input = self.create_subscription(PoseStamped, topics.PLATFORM_POSE, self._on_pose, RELIABLE_QOS)
        self.resets = 0
        self.create_service(Trigger, '~/reset', self._srv_reset)
        self._publisher_seen = False  # a publisher of the held input seen in the graph since
        self.create_timer(SESSION_CHECK_S, self._check_session)
        self.diagnostics = Diagnostics(self, self._report)

    def _validate(self, values: dict[str, Any]):
        built = _validate(values)
        if self.device is not None:
            check(built[0].register + built[0].count <= self.device.registers, 'register', values['register'],
                  f'must lie in the {self.device.registers} registers served')
        check_start_only(values, self.settings, START_ONLY)
        return built

    def _apply(self, built, values: dict[str, Any]) -> None:
        channel, model = built
        if self.zero_pose is not None:
            model.zero(self.zero_pose[:3], self.zero_pose[3:].reshape(3, 3))  # a new set-up keeps the zero
        self.model = model
        if self.device is None:
            self.device = ModbusDevice(self._reading, channel=channel, host=values['host'], port=values['port'],
                                       unit_id=values['unit_id'], registers=max(64, channel.register + 2))
            self.device.start()  # DriverError (cannot listen) stops the start with the reason
            self.get_logger().info(f'serving Modbus TCP on {self.device.host}:{self.device.port}, unit '
                                   f'{values["unit_id"]}, {channel.data_type} at register {channel.register}')
        else:
            self.device.channel = channel
        self.settings = values

    def _reading(self) -> float | None:
        """The LVDT model's reading of the held pose [m], None before the first pose (the server thread calls this
        on every read)."""
        pose = self.pose
        if pose is None:
            return None
        assert self.model is not None
        reading, _ = self.model.measure(pose[:3], pose[3:].reshape(3, 3), time.monotonic() - self.t0)
        return reading

    def _on_pose(self, msg: PoseStamped) -> None:
        self.counters.received += 1
        self.lag.add(msg.header.stamp, self.get_clock().now().nanoseconds * 1e-9, self.settings['max_input_lag_s'])
        pose = pose_vector(msg)
        if pose is None:
            self.counters.dropped_non_finite += 1
            return
        if self.zero_pose is None and self.settings['zero_on_first_pose']:
            assert self.model is not None
            self.model.zero(pose[:3], pose[3:].reshape(3, 3))
            self.zero_pose = pose
        self.pose = pose
        self.counters.used += 1

    def reset(self, why: str) -> None:
        """Forget the held pose and the zero taken on the first one: reads answer busy until the next pose."""
        if self.pose is not None:
            self.pose = None
            self.zero_pose = None
            self.resets += 1
            self.get_logger().info(f'{why}: the held pose and its zero are forgotten; reads answer "busy" until the '
                                   'next platform pose')

    def _check_session(self) -> None:
        """The session's crane_model gone (no publisher of the platform pose left): its platform is no longer there."""
        # Only a publisher seen in the graph and gone again counts: the graph may show a publisher later than its
        # first message arrives, and a reset then would leave the rig waiting for a reading that never comes.
        publishers = self.count_publishers(self.input.topic_name)  # (as remapped)
        if publishers:
            self._publisher_seen = True
        elif self._publisher_seen and self.pose is not None:
            self._publisher_seen = False
            self.reset(f'no publisher of {topics.PLATFORM_POSE} left (the session ended)')

    def _srv_reset(self, request, response):
        self.reset('~/reset')
        response.success, response.message = True, f'reads answer busy until the next {topics.PLATFORM_POSE}'
        return response

    def _report(self):
        self.counters.published = self.device.reads
        late, lag_pairs = self.lag.status('the platform pose', self.settings['max_input_lag_s'])
        pairs = self.counters.as_pairs() + [('port', str(self.device.port)),
                                            ('zeroed', str(self.zero_pose is not None).lower()),
                                            ('resets', str(self.resets)),
                                            ('zero_offset_m', repr(self.model.zero_offset))] + lag_pairs
        if late:
            return WARN, late, pairs
        if self.pose is None:
            return (WARN, f'no platform pose yet on {topics.PLATFORM_POSE}: every read answers "server device busy"',
                    pairs)
        return OK, f'serving Modbus TCP on {self.device.host}:{self.device.port}, {self.device.reads} reads', pairs

    def close(self) -> None:
        if self.device is not None:
            self.counters.published = self.device.reads
            self.device.stop()


def main(args=None) -> int:
    return run(ModbusEmulator, args)


if __name__ == '__main__':
    raise SystemExit(main())
