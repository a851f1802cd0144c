"""What the load_program node does beyond playing its program (a mixin of crane_stiffness.nodes.load_program's node):
the operator's part when ``load_application`` is ``operator`` (hold at each new level until it is confirmed by a
~/confirm call or by the measured load settling there) and the tare and zero at the unloaded state before the first
step (``tare_services``). The rules themselves (where the levels are, when a load has settled) are pure:
crane_stiffness.sim.program (``load_prompts``, ``Settling``)."""
from __future__ import annotations

import getpass
import time
from datetime import datetime, timezone
from typing import Any

from geometry_msgs.msg import WrenchStamped
from rclpy.clock import Clock, ClockType
from rclpy.timer import Timer
from std_srvs.srv import Trigger

from crane_stiffness.contract.axes import AXES
from crane_stiffness.sim.program import AXIS_UNITS, LoadPrompt, Settling

#: How long the tare waits for each of its services to be there [s] (a driver still connecting to its device).
TARE_WAIT_S = 60.0


def utc_now() -> str:
    """Now as UTC ISO 8601, to the millisecond."""
    return datetime.now(timezone.utc).isoformat(timespec='milliseconds')


class LoadApplication:
    """The operator's levels and the unloaded-state tare of the load_program node (it sets the attributes below in
    its ``__init__`` and calls :meth:`_begin` to start from idle)."""

    # Set by the node (crane_stiffness.nodes.load_program.LoadProgramNode).
    params: Any
    state: str
    elapsed: float
    started_at: float | None
    exit_status: int
    prompts: list[LoadPrompt]
    prompt_index: int
    confirmations: list[dict[str, Any]]
    _settling: Settling | None
    tare: list[dict[str, Any]]
    _tare_todo: list[str] | None
    _tare_timer: Timer | None
    _tare_future: Any
    _tare_client: Any
    _tare_wait_started: float
    exit_requested: bool

    def _start(self, at_s: float | None = None) -> str:
        raise NotImplementedError  # (the node's)

    def _publish_state(self) -> None:
        raise NotImplementedError  # (the node's)

    def _now(self) -> float:
        raise NotImplementedError  # (the node's)

    @property
    def _operator_mode(self) -> bool:
        return self.params['load_application'] == 'operator'

    def _who(self) -> str:
        """Who runs the test: the ``operator`` parameter, else the login name of this process."""
        if self.params['operator']:
            return str(self.params['operator'])
        try:
            return getpass.getuser()
        except (OSError, KeyError):
            return ''

    # --- tare and zero at the unloaded state ---
    def _begin(self) -> str:
        """Start from idle: first the tare services (once), then the program."""
        if self._tare_todo is None and any(str(v).strip() for v in self.params['tare_services']):
            self._tare_todo = [str(v).strip() for v in self.params['tare_services'] if str(v).strip()]
            self.state = 'taring'
            self._publish_state()
            self._node().get_logger().info('taring at the unloaded state before the first step: '
                                           + ', '.join(self._tare_todo))
            self._tare_timer = self._node().create_timer(0.1, self._tare_step,
                                                         clock=Clock(clock_type=ClockType.STEADY_TIME))
            return f'taring first ({", ".join(self._tare_todo)}), then running'
        if self.state == 'taring':
            return 'taring first'
        return self._start()

    def _tare_step(self) -> None:
        """One step of the tare: wait for the next service, call it, keep its answer; then start the program."""
        assert self._tare_todo is not None
        if self._tare_future is not None:
            if not self._tare_future.done():
                return
            answer = self._tare_future.result()
            service = self._tare_todo.pop(0)
            entry = {'service': service, 'success': bool(answer and answer.success),
                     'message': '' if answer is None else str(answer.message), 'at_utc': utc_now(), 'by': self._who()}
            self.tare.append(entry)
            self._tare_future = None
            self._node().destroy_client(self._tare_client)
            self._tare_client = None
            if not entry['success']:
                return self._tare_failed(f'{service} answered: {entry["message"] or "failure"}')
            self._node().get_logger().info(f'{service}: {entry["message"]}')
        if not self._tare_todo:
            assert self._tare_timer is not None
            self._node().destroy_timer(self._tare_timer)
            self._tare_timer = None
            self.state = 'idle'
            self._start()
            return
        if self._tare_client is None:
            self._tare_client = self._node().create_client(Trigger, self._tare_todo[0])
            self._tare_wait_started = time.monotonic()
        if not self._tare_client.service_is_ready():
            if time.monotonic() - self._tare_wait_started > TARE_WAIT_S:
                self._tare_failed(f'{self._tare_todo[0]}: no such service after {TARE_WAIT_S:g} s')
            return
        self._tare_future = self._tare_client.call_async(Trigger.Request())

    def _tare_failed(self, why: str) -> None:
        if self._tare_timer is not None:
            self._node().destroy_timer(self._tare_timer)
            self._tare_timer = None
        self.state = 'stopped'
        self.tare.append({'failed': why, 'at_utc': utc_now(), 'by': self._who()})
        self._publish_state()
        self._node().get_logger().error(f'tare at the unloaded state failed, the program does not start: {why}')
        self.exit_status = 1
        self.exit_requested = True

    # --- load_application operator ---
    def _wait_for_operator(self, prompt: LoadPrompt) -> None:
        """Hold the program at ``prompt``'s level until it is confirmed."""
        self.elapsed = prompt.time_s
        self.state = 'waiting'
        if self.params['operator_settle_s'] > 0:
            self._settling = Settling(prompt.level, self.params['operator_tolerance'],
                                      self.params['operator_settle_s'])
        self._publish_state()
        how = ('call /load_program/confirm when it is on' + (
            f', or wait: the measured {prompt.axis} within {self.params["operator_tolerance"]:g} '
            f'{AXIS_UNITS[prompt.axis]} of it for {self.params["operator_settle_s"]:g} s confirms it'
            if self._settling is not None else ''))
        self._node().get_logger().info(f'{prompt.text(len(self.prompts))}; {how}')

    def _confirm(self, how: str) -> str:
        prompt = self.prompts[self.prompt_index]
        self.confirmations.append({'level': prompt.index + 1, 'axis': prompt.axis, 'value': prompt.level,
                                   'how': how, 'at_utc': utc_now(), 'by': self._who()})
        self.prompt_index += 1
        self._settling = None
        self.started_at = self._now()
        self.state = 'running'
        self._publish_state()
        text = f'level {prompt.index + 1}/{len(self.prompts)} ({prompt.axis} = {prompt.level:g}) confirmed ({how})'
        self._node().get_logger().info(text)
        return text

    def _srv_confirm(self, request, response):
        if self.state != 'waiting':
            response.success, response.message = False, f'nothing to confirm (state {self.state})'
            return response
        response.success, response.message = True, self._confirm('service ~/confirm')
        return response

    def _on_measured(self, msg: WrenchStamped) -> None:
        if self.state != 'waiting' or self._settling is None:
            return
        prompt = self.prompts[self.prompt_index]
        w = msg.wrench
        value = [w.force.x, w.force.y, w.force.z, w.torque.x, w.torque.y, w.torque.z][AXES.index(prompt.axis)]
        stamp = msg.header.stamp.sec + msg.header.stamp.nanosec * 1e-9
        if self._settling.update(stamp, float(value)):
            self._confirm(f'measured {prompt.axis} settled within {self._settling.tolerance:g} '
                          f'{AXIS_UNITS[prompt.axis]} for {self._settling.hold_s:g} s')

    def _node(self) -> Any:
        return self


__all__ = ['LoadApplication', 'TARE_WAIT_S', 'utc_now']
