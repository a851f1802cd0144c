"""What the live stiffness estimators read of the rig's other nodes to state U and E_n: the load cell's and the LVDT's
declared calibrations (their ``calibration.*``, ``full_scale`` and ``range_m`` parameters; the live 6×6 estimator the
load cell's, the pose sensor's and an LVDT array's, :data:`KINDS`) and the crane model's
geometry (its ``geometry.*``, the crane file), over ROS as the session recorder reads them
(:class:`~crane_stiffness.rosnode.parameter_reader.NodeParameterReader`), at start and again when one of those nodes
reports a change of them on /parameter_events. The calibrations go to the live core
(:attr:`LiveStiffness.calibrations <crane_stiffness.estimation.live.LiveStiffness>`), the geometry to the model
prediction's relative U (:func:`~crane_stiffness.estimation.live_uncertainty.prediction_relative_uncertainty`, once
per geometry and axis, on a thread of its own: loading the model's compiled kernels takes seconds of wall-clock time
on a busy machine, and the estimator's callbacks go on meanwhile).

Of each kind the first node of its list that answers is the one read (``/load_cell`` or the driver ``/netft``; the
others' clients are closed then): a node absent from the rig costs a readiness check every half second, nothing once
every kind is read.

On simulated time the estimator's watermarks wait for the reads (:meth:`EstimatorReferences.holds`) while a node to
read is in the graph, at most :data:`WAIT_S` of wall-clock time: its statuses then say the same in every run
(the same U from the first estimate on), as the rest of a session on simulated time does.
"""
from __future__ import annotations

import math
import threading
import time
from typing import Any, Callable, Sequence

from rcl_interfaces.msg import ParameterEvent
from rclpy.clock import Clock, ClockType
from rclpy.node import Node
from rclpy.qos import qos_profile_parameter_events

from crane_stiffness.errors import CraneStiffnessError
from crane_stiffness.estimation.live import LiveStiffness
from crane_stiffness.estimation.live_uncertainty import prediction_relative_uncertainty
from crane_stiffness.rosnode.parameter_reader import NodeParameterReader

#: The kinds read, and which of a node's parameters matter for each (a change of any other is ignored). An
#: estimator reads the kinds it names nodes for (the one-axis one load_cell, lvdt and model; the 6×6 one load_cell,
#: pose_sensor and lvdt_array).
KINDS = ('load_cell', 'lvdt', 'model', 'pose_sensor', 'lvdt_array')
_RELEVANT: dict[str, Callable[[str], bool]] = {
    'load_cell': lambda name: name.startswith('calibration.') or name == 'full_scale',
    'lvdt': lambda name: name.startswith('calibration.') or name == 'range_m',
    'model': lambda name: name.startswith('geometry.'),
    'pose_sensor': lambda name: name.startswith('calibration.'),
    'lvdt_array': lambda name: name.startswith('calibration.'),
}
#: How often the reads are advanced while one is pending [s] (steady clock: also on simulated time).
POLL_PERIOD_S = 0.5
#: On simulated time, the longest the estimator's watermarks wait for a node in the graph to answer [s, wall].
WAIT_S = 60.0


class EstimatorReferences:
    """Reads the nodes ``nodes[kind]`` (kinds :data:`KINDS`) for the live core ``core()`` (the node's; None before
    its first settings), the prediction's uncertainty file from ``uncertainty_file()``. A calibration read goes to
    ``on_calibration(kind, values)`` when given (the 6×6 estimator's), else into the core's ``calibrations``."""

    def __init__(self, node: Node, nodes: dict[str, Sequence[str]], core: Callable[[], LiveStiffness | None],
                 uncertainty_file: Callable[[], str],
                 on_calibration: Callable[[str, dict[str, Any]], None] | None = None) -> None:
        self._node = node
        self._on_calibration = on_calibration
        self._nodes = {kind: ['/' + n.strip('/') for n in nodes.get(kind, ()) if n.strip('/')] for kind in KINDS}
        self._core = core
        self._uncertainty_file = uncertainty_file
        self.read_from: dict[str, str] = {}  # kind -> the node read (without '/')
        self.geometry: dict[str, Any] | None = None  # the model node's geometry.*, once read
        self._predicted: tuple | None = None  # (geometry, axis, file) of the prediction's U now in the core
        # the prediction being computed on a thread of its own (loading the model's compiled kernels takes seconds
        # of wall-clock time on a busy machine: the estimator's callbacks go on meanwhile), and its result
        self._computing: threading.Thread | None = None
        self._computed: tuple[str, str, str, float, float, str] | None = None  # axis, unit, path, value, U/k, error
        self._readers: dict[str, NodeParameterReader] = {}
        self._held: tuple[int, Callable[[int], None]] | None = None  # a watermark waiting for the reads
        self._since = time.monotonic()
        self._gave_up = False
        for kind in KINDS:
            self._start(kind, self._nodes[kind])
        self._timer = node.create_timer(POLL_PERIOD_S, self._poll, clock=Clock(clock_type=ClockType.STEADY_TIME))
        node.create_subscription(ParameterEvent, '/parameter_events', self._on_event, qos_profile_parameter_events)

    @property
    def pending(self) -> list[str]:
        """The kinds not read yet."""
        return [kind for kind in KINDS if kind in self._readers]

    def _start(self, kind: str, names: Sequence[str]) -> None:
        if names and kind not in self._readers:
            self._readers[kind] = NodeParameterReader(self._node, names,
                                                      lambda node, values: self._read(kind, node, values))

    def _poll(self) -> None:
        for reader in list(self._readers.values()):
            reader.poll()
        self._take_prediction()
        self._release()
        if not self._readers and self._held is None and self._computing is None:
            self._timer.cancel()

    def _read(self, kind: str, node: str, values: dict[str, Any]) -> None:
        reader = self._readers.pop(kind, None)
        if reader is not None:
            reader.close()  # the other candidates of this kind: not read
        self.read_from[kind] = node
        values = {k: v for k, v in values.items() if _RELEVANT[kind](k)}
        core = self._core()
        log = self._node.get_logger()
        if kind == 'model':
            self.geometry = values
            log.info(f"the model's geometry of /{node} read: the prediction's U is computed")
            self.update_prediction()
            return
        if self._on_calibration is not None:
            self._on_calibration(kind, values)
        elif core is not None:
            load_cell, lvdt = core.calibrations
            core.calibrations = (values, lvdt) if kind == 'load_cell' else (load_cell, values)
        else:
            return
        declared = sorted({k.split('.')[1].removesuffix('_distribution').removesuffix('_k') for k in values
                           if k.startswith('calibration.')})
        log.info(f'U of the live estimate: the {kind} calibration of /{node} read ({", ".join(declared) or "none"})')

    def update_prediction(self) -> None:
        """The model prediction's relative U along the core's axis (GUM linear law; computed again only when the
        geometry, the axis or the uncertainty file changed)."""
        core = self._core()
        if core is None or self.geometry is None:
            return
        axis, unit, path = core.settings.force_axis, core.settings.stiffness_unit, self._uncertainty_file()
        key = (sorted(self.geometry.items()), axis, path)
        if key == self._predicted:
            return
        self._predicted = key
        core.prediction_relative_U = math.nan  # (none while the new one is computed)
        geometry = dict(self.geometry)

        def compute() -> None:
            try:
                value, relative = prediction_relative_uncertainty(geometry, axis, path)
                self._computed = (axis, unit, path, value, relative, '')
            except (CraneStiffnessError, ValueError, OSError) as exc:
                self._computed = (axis, unit, path, math.nan, math.nan, str(exc))
            except Exception as exc:  # noqa: BLE001 (a thread's error would only go to stderr: said in the log)
                self._computed = (axis, unit, path, math.nan, math.nan, f'{type(exc).__name__}: {exc}')
        if self._computing is not None:
            self._computing.join()  # (an older one: its result is dropped below, the key has changed)
            self._computed = None
        self._computing = threading.Thread(target=compute, name='prediction_uncertainty', daemon=True)
        self._computing.start()
        if self._timer.is_canceled():
            self._timer.reset()

    def _take_prediction(self) -> None:
        """The prediction's U, once its thread is done: into the core (on the executor's thread)."""
        if self._computing is None or self._computing.is_alive():
            return
        self._computing, done, self._computed = None, self._computed, None
        core = self._core()
        if done is None or core is None:
            return
        axis, unit, path, value, relative, error = done
        log = self._node.get_logger()
        if error:
            log.warn(f"the model's prediction with its uncertainty failed, no E_n: {error}")
            return
        if axis == core.settings.force_axis:
            core.prediction_relative_U = relative
            log.info(f'model prediction along {axis} at rest: {value:.6g} ± {relative * value:.4g} {unit} (U, 95 %, '
                     f'GUM linear law; {path}): E_n live')

    def _on_event(self, event: ParameterEvent) -> None:
        """A node read reports changed parameters: read it again if one of them matters."""
        node = event.node.lstrip('/')
        for kind, read in list(self.read_from.items()):
            changed = [p.name for p in list(event.new_parameters) + list(event.changed_parameters)]
            if node == read and any(_RELEVANT[kind](name) for name in changed):
                self._start(kind, ['/' + node])
                if self._timer.is_canceled():
                    self._timer.reset()

    # --- simulated time ---
    def holds(self, t_ns: int, report: Callable[[int], None]) -> bool:
        """Simulated time: True when the watermark ``t_ns`` must wait for a read (a node to read is in the graph
        and has not answered, for less than :data:`WAIT_S`); ``report(t_ns)`` is called once it has."""
        if not self._waiting():
            self._held = None
            return False
        self._held = (t_ns, report)
        if self._timer.is_canceled():
            self._timer.reset()
        return True

    def _waiting(self) -> bool:
        present = {('/' + ns.strip('/') + '/' + name).replace('//', '/')
                   for name, ns in self._node.get_node_names_and_namespaces()}
        waiting = [kind for kind in self.pending if present & set(self._nodes[kind])]
        if self._computing is not None:
            waiting.append("the model prediction's U")
        if not waiting:
            return False
        if time.monotonic() - self._since < WAIT_S:
            return True
        if not self._gave_up:
            self._gave_up = True
            self._node.get_logger().warn(f'simulated time waited {WAIT_S:g} s for {", ".join(waiting)}: going on '
                                         'without (U statistical only for a sensor not read, no E_n without the '
                                         'model)')
        return False

    def _release(self) -> None:
        if self._held is not None and not self._waiting():
            (t_ns, report), self._held = self._held, None
            report(t_ns)

    def close(self) -> None:
        for reader in self._readers.values():
            reader.close()
        self._readers.clear()
        self._timer.cancel()


__all__ = ['KINDS', 'POLL_PERIOD_S', 'WAIT_S', 'EstimatorReferences']
