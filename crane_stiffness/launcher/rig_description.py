"""The simulated rig as data: which nodes run, which parameter files and parameters each gets, which arguments
choose them. Pure Python (no ROS, no launch import): ``launch/rig.launch.py`` builds its launch description from
it for ``ros2 launch``, and crane_stiffness.launcher.rig starts the same nodes as processes for the demo, the tests
and the benchmarks.

    ros2 launch crane_stiffness rig.launch.py program:=side_force record:=true

Arguments (:data:`ARGUMENTS`): program (side_force | side_force_slack | moment_z | force_z, or a path to a program
YAML), crane (a geometry YAML; default the lab model), sensors (sensor YAML), sim_sensors and record (true/false),
session (bag name), transport and drivers (below), live_view (true/false) and its view_host, view_port,
view_http_port.

``transport`` says how the sensor readings reach the estimator:

- ``sim`` (default): the simulated sensors ``load_cell`` and ``lvdt`` publish /load_cell/wrench and
  /lvdt/displacement directly.
- ``drivers``: through the device protocols and the real drivers. The simulated physics is served as devices on
  127.0.0.1 (``rdt_emulator``: an RDT F/T sensor on UDP; ``modbus_emulator``: a Modbus TCP analog input), and the
  hardware drivers ``netft`` and ``modbus_lvdt`` read them and publish the two topics. Every one of those four
  nodes reads the ``drivers`` file (default config/drivers_emulated.yaml: the addresses, ports, rates and
  calibration of both sides). With ``sim_sensors:=false`` the emulators do not start and the drivers talk to real
  hardware: give a drivers file with the devices' addresses (config/drivers_ati_labjack.yaml,
  config/drivers_onrobot_labjack.yaml; see docs/hardware.md).

Each node also says which machine of the lab it belongs on (:attr:`RigNode.machine`): 'daq' (the rig PC: model,
program, sensors, drivers and emulators) or 'analysis' (estimator and recorder). ``machine`` (all | daq |
analysis) starts only that machine's nodes, so one launch per PC runs the rig across the lab network; load_program
still waits for every node of the whole rig (those on the other PC too). The lab network test places the nodes in
two network namespaces by it.

Every node starts at the same instant (as ``ros2 launch`` starts them); load_program starts the program only when
the rig is ready. What "ready" means follows from the nodes started (:func:`readiness`): a message on the model's
prediction and on both sensor streams, and each started node subscribed to the topics it reads. An unknown program
or a missing parameter file raises :class:`RigError` naming the file before anything starts; so do what can only be
typos: an argument the rig does not declare (``transprot:=drivers``, :func:`check_argument_names`; launch itself
would take it silently) and a parameter-file section that applies to no node of the rig (``stiffness_estimater:``,
read by none), each with the closest declared name.
"""
from __future__ import annotations

import os
from dataclasses import dataclass, field
from typing import Any, Iterable, Mapping

from crane_stiffness import PACKAGE

from crane_stiffness.contract import topics
from crane_stiffness.contract.control_events import RECORDER_CUT_STATUS
from crane_stiffness.errors import CraneStiffnessError
from crane_stiffness.params.errors import ConfigError
from crane_stiffness.params.files import ParamFile, check_sections, did_you_mean

__all__ = ['ARGUMENTS', 'LAUNCH_OWN', 'MACHINES', 'NODES', 'PACKAGE', 'SIGKILL_AFTER_S', 'TRANSPORTS', 'Argument',
           'NodeStart', 'RigError', 'RigNode', 'argument_values', 'check_argument_names', 'check_file_sections',
           'config_files', 'config_path', 'exit_problem', 'flag', 'known_programs', 'program_file', 'readiness',
           'rig_nodes']


class RigError(CraneStiffnessError, ValueError):
    """The rig cannot start as asked: an unknown program, a missing parameter file, an unknown argument."""


@dataclass(frozen=True)
class Argument:
    """A launch argument of the rig. ``config_file``: its default names a file in the package's config/ directory."""

    name: str
    default: str
    description: str
    config_file: bool = False


ARGUMENTS: tuple[Argument, ...] = (
    Argument('program', 'side_force', 'test program name or file'),
    Argument('crane', 'crane_lab.yaml', 'crane geometry parameters (ROS parameter YAML; a bare file name is one of '
             "the package's config/)", config_file=True),
    Argument('sensors', 'sensors.yaml', "sensor and estimator parameters (a bare file name is one of config/)",
             config_file=True),
    Argument('sim_sensors', 'true', 'start the simulated sensors'),
    Argument('record', 'true', 'record the session to bags/'),
    Argument('session', '', 'bag name (default: time stamped)'),
    Argument('transport', 'sim', "how the sensor readings reach the estimator: 'sim' = the simulated sensors publish "
             "them; 'drivers' = through the device protocols (RDT, Modbus TCP) and the drivers netft, modbus_lvdt"),
    Argument('drivers', 'drivers_emulated.yaml', 'driver (and device emulator) parameters, read with '
             'transport:=drivers (a bare file name is one of config/)', config_file=True),
    Argument('machine', 'all', "start the nodes of one lab machine only: 'daq' (model, program, sensors, drivers), "
             "'analysis' (estimator, recorder, live view), or 'all'"),
    Argument('live_view', 'false', 'start live_view: the page and a Foxglove WebSocket server (docs/live_view.md)'),
    Argument('view_host', '127.0.0.1', "address the live view listens on (0.0.0.0: the lab network)"),
    Argument('view_port', '8765', "the live view's Foxglove WebSocket port"),
    Argument('view_http_port', '8080', "the live view's page port"),
    Argument('use_sim_time', 'false', 'simulated time: sim_clock publishes /clock and every node follows it; time '
             'slows down when the machine is busy instead of samples being lost (transport:=sim only)'),
    Argument('six_axis', 'auto', "the whole 6x6 stiffness: a pose sensor (the simulated pose_sensor, or a tracker "
             "remapped onto /pose_sensor/pose) and stiffness6_estimator; 'auto': when the program file has a "
             "stiffness6_estimator section (program:=full6)"),
    Argument('real_time_factor', '1.0', "with use_sim_time: simulated seconds per wall second (0 or 'max': as fast "
             'as the rig keeps up)'),
)
#: The values of the ``transport`` argument.
TRANSPORTS = ('sim', 'drivers')
#: The machines of the lab a node belongs on (see :attr:`RigNode.machine`).
MACHINES = ('daq', 'analysis')


@dataclass(frozen=True)
class RigNode:
    """One node of the rig (node name = executable name).

    ``files``: the parameter files it reads, in order, by role: 'crane', 'sensors', 'drivers' (the arguments of
    those names) or 'program' (the program's file). ``arguments``: parameters set from arguments, {parameter: argument}.
    ``condition``: the true/false argument that starts it (None: always). ``when``: (argument, value) pairs that
    must all hold for it to start (e.g. ('transport', 'drivers')). ``remappings``: (from, to) topic pairs.
    ``runs_program``: the node that plays the program; it starts with the others and waits until the rig is ready.
    ``reads``: topics the program must not start before this node subscribes to (nothing of them may be lost).
    ``machine``: where it runs in the lab: 'daq' (the rig PC, with the sensors' devices) or 'analysis'.
    """

    executable: str
    files: tuple[str, ...]
    arguments: Mapping[str, str] = field(default_factory=dict)
    condition: str | None = None
    when: tuple[tuple[str, str], ...] = ()
    remappings: tuple[tuple[str, str], ...] = ()
    runs_program: bool = False
    reads: tuple[str, ...] = ()
    machine: str = 'daq'
    #: Parameters of ``arguments`` given as integers (launch hands a plain string to the node as a string).
    integers: tuple[str, ...] = ()
    #: Parameters of ``arguments`` given as floating-point numbers.
    floats: tuple[str, ...] = ()
    #: Its stage in simulated time (crane_stiffness.sim.lockstep): the clock waits for it; None: not a participant.
    sim_stage: int | None = None
    #: A boolean parameter set to whether the program is a six-axis test (:func:`is_six_axis_program`): the one-axis
    #: estimator says it does not apply then, the live view leads with the 6×6.
    six_axis_parameter: str | None = None

    @property
    def name(self) -> str:
        return self.executable


_STREAMS = (topics.LOAD_CELL_WRENCH, topics.LVDT_DISPLACEMENT)

_SIM = (('transport', 'sim'),)
_DRIVERS = (('transport', 'drivers'),)

NODES: tuple[RigNode, ...] = (
    # On simulated time a clock source drives every node (see crane_stiffness.sim.lockstep).
    RigNode('sim_clock', (), condition='use_sim_time', arguments={'real_time_factor': 'real_time_factor'},
            floats=('real_time_factor',)),
    RigNode('crane_model', ('crane', 'program'), reads=(topics.WRENCH_COMMAND,), sim_stage=1),
    RigNode('load_cell', ('sensors',), condition='sim_sensors', when=_SIM, reads=(topics.APPLIED_WRENCH,),
            sim_stage=2),
    RigNode('lvdt', ('sensors', 'program'), condition='sim_sensors', when=_SIM, reads=(topics.PLATFORM_POSE,),
            sim_stage=2),
    RigNode('pose_sensor', ('sensors', 'program'), condition='six_axis', when=(*_SIM, ('sim_sensors', 'true')),
            reads=(topics.PLATFORM_POSE,), sim_stage=2),
    # transport:=drivers: the simulated physics served as devices (only with sim_sensors), read by the drivers.
    RigNode('rdt_emulator', ('drivers',), condition='sim_sensors', when=_DRIVERS,
            reads=(topics.APPLIED_WRENCH,)),
    RigNode('modbus_emulator', ('drivers', 'program'), condition='sim_sensors', when=_DRIVERS,
            reads=(topics.PLATFORM_POSE,)),
    RigNode('netft', ('drivers',), when=_DRIVERS),
    RigNode('modbus_lvdt', ('drivers',), when=_DRIVERS),
    # The program file holds its series' measuring arrangement (the LVDT's axis and contact point, the fitted axis,
    # the prediction's axis): the model, the displacement sensor and the estimator read it after their own files.
    # With transport:=drivers the estimator reads the drivers file last: how to pair depends on the drivers' rates
    # (a 1 kHz F/T sensor and a 100 Hz DAQ: pairing interpolate_force), and a lab's file may set its lever arm.
    RigNode('stiffness_estimator', ('crane', 'sensors', 'program', 'drivers'), reads=(topics.WRENCH_COMMAND, *_STREAMS),
            machine='analysis', sim_stage=3, six_axis_parameter='six_axis_program'),
    # The 6x6 fit of a program whose file says so (program:=full6, six_axis): the load cell and a pose sensor.
    RigNode('stiffness6_estimator', ('sensors', 'program'), condition='six_axis',
            reads=(topics.WRENCH_COMMAND, topics.LOAD_CELL_WRENCH, topics.POSE_SENSOR_POSE), machine='analysis',
            sim_stage=3),
    RigNode('session_recorder', ('crane', 'sensors', 'program'), arguments={'session': 'session'},
            condition='record', reads=(topics.WRENCH_COMMAND, topics.APPLIED_WRENCH, topics.REJECTED_COMMAND,
                                        topics.PLATFORM_POSE, *_STREAMS), machine='analysis', sim_stage=3),
    RigNode('load_program', ('program',), runs_program=True, sim_stage=0),
    # For people watching: reads the rig's topics, waits for nothing, and the program does not wait for it.
    RigNode('live_view', ('crane',), condition='live_view', machine='analysis',
            arguments={'host': 'view_host', 'port': 'view_port', 'http_port': 'view_http_port'},
            integers=('port', 'http_port'), six_axis_parameter='six_axis_program'),
)
#: Topics a message must have arrived on before the program starts: the model's prediction (latched) and both
#: sensor streams (from the simulated sensors, or from real drivers remapped onto them).
READY_MESSAGES: tuple[str, ...] = (topics.PREDICTED_AXIS_STIFFNESS, *_STREAMS)


@dataclass(frozen=True)
class NodeStart:
    """A node as it is started for given arguments: parameter files (paths), parameters, remappings."""

    name: str
    executable: str
    parameter_files: tuple[str, ...]
    parameters: dict[str, Any]
    remappings: tuple[tuple[str, str], ...]
    runs_program: bool
    machine: str = 'daq'


def program_file(program: str, config_dir: str | os.PathLike) -> str:
    """The parameter file of a program: a path ending in .yaml as it is, else ``<config_dir>/program_<name>.yaml``."""
    return program if program.endswith('.yaml') else os.path.join(config_dir, f'program_{program}.yaml')


def known_programs(config_dir: str | os.PathLike) -> list[str]:
    """The program names ``config_dir`` holds files for (program_<name>.yaml)."""
    try:
        names = os.listdir(config_dir)
    except OSError:
        return []
    return sorted(n[len('program_'):-len('.yaml')] for n in names if n.startswith('program_') and n.endswith('.yaml'))


def flag(value: str | bool) -> bool:
    """A true/false argument as launch's IfCondition reads it ('true'/'1', 'false'/'0', any case)."""
    if isinstance(value, bool):
        return value
    if value.strip().lower() in ('true', '1'):
        return True
    if value.strip().lower() in ('false', '0'):
        return False
    raise ValueError(f'{value!r}: expected true or false')


#: Launch configurations that launch and launch_ros set or read themselves (``ros2 launch --launch-prefix``,
#: ``emulate_tty``, ``sigterm_timeout:=``/``sigkill_timeout:=``: how long launch waits at Ctrl-C; PushRosNamespace,
#: SetRemap, SetParameter): in the launch context beside the rig's arguments, never a typo of one.
LAUNCH_OWN = frozenset({'launch-prefix', 'launch-prefix-filter', 'emulate_tty', 'sigterm_timeout', 'sigkill_timeout',
                        'ros_namespace', 'ros_remaps', 'global_params'})


#: Ctrl-C: how long launch waits after its SIGTERM (itself 5 s after the SIGINT) before it kills a node [s]. Every
#: node holds both signals while its interpreter starts and ends cleanly once started, but on a busy two-core machine
#: (load 15) starting took longer than launch's default 5 s: the whole rig was killed, the recorder's bag unclosed.
#: ``sigkill_timeout:=S`` on the command line still sets it (launch's own configuration).
SIGKILL_AFTER_S = 55.0


def check_argument_names(names: Iterable[str], launch_own: Iterable[str] = LAUNCH_OWN) -> None:
    """RigError naming the first argument in ``names`` the rig does not declare (``launch_own``: the launch
    configurations of launch itself, aside) and the closest declared one: ``ros2 launch`` takes any
    ``name:=value`` and the rig would run without it (``sim_sensor:=false`` starting the emulators all the same)."""
    declared = [a.name for a in ARGUMENTS]
    for name in sorted(set(names) - set(declared) - set(launch_own)):
        hint = did_you_mean(name, declared) or f"; the rig's arguments: {', '.join(declared)}"
        raise RigError(f'{name}:=...: the rig has no argument {name!r}{hint} (ros2 launch crane_stiffness '
                       'rig.launch.py --show-args lists them)')


def argument_values(config_dir: str | os.PathLike, given: Mapping[str, str | bool] | None = None) -> dict[str, Any]:
    """Every argument's value: the given ones, else the defaults (config files in ``config_dir``); RigError names an
    argument the rig does not declare (:func:`check_argument_names`)."""
    given = dict(given or {})
    check_argument_names(given, launch_own=())
    values = {a.name: given.get(a.name, a.default) for a in ARGUMENTS}
    for a in ARGUMENTS:
        if a.config_file:
            values[a.name] = config_path(values[a.name], config_dir)
    return values


def config_path(value: str | bool, config_dir: str | os.PathLike) -> str:
    """A parameter-file argument as a path: a bare file name (no directory part, as the defaults are) names a file
    in the package's config/ directory; anything else is a path as given (``./mine.yaml`` for one here)."""
    value = str(value)
    return os.path.join(config_dir, value) if value and os.path.basename(value) == value else value


def config_files(config_dir: str | os.PathLike, given: Mapping[str, str | bool] | None = None) -> dict[str, str]:
    """The parameter file of each role ('crane', 'sensors', 'program') for the arguments ``given``; RigError names
    a file that does not exist (for a program name, with the programs there are)."""
    values = argument_values(config_dir, given)
    files = {'crane': str(values['crane']), 'sensors': str(values['sensors']),
             'program': program_file(str(values['program']), config_dir), 'drivers': str(values['drivers'])}
    for role, path in files.items():
        if role == 'drivers' and values['transport'] != 'drivers':
            continue  # read only by the drivers' nodes
        if os.path.isfile(path):
            continue
        if role == 'program' and not str(values['program']).endswith('.yaml'):
            raise RigError(f"unknown program {values['program']!r}: no file {path}; known programs: "
                           f"{', '.join(known_programs(config_dir)) or 'none'} (or give a program YAML file)")
        raise RigError(f'{role} file {path} not found ({role}:=...)')
    return files


def readiness(started: list[RigNode]) -> dict[str, list[str]]:
    """load_program's wait_for_messages and wait_for_subscribers for the nodes ``started`` (see load_program)."""
    readers: dict[str, list[str]] = {}
    for node in started:
        for topic in node.reads:
            readers.setdefault(topic, []).append(node.name)
    messages = list(READY_MESSAGES)
    if any(node.name == 'stiffness_estimator' for node in started):
        # The estimator subscribed (the graph shows it) is not the estimator receiving: until its own start-up is
        # done and its readers matched the sensors, the start of the program overflows its queues unseen (it counts
        # losses from its first sample on; once it missed the first 1.5 s of the loading ramp). Its first estimate
        # values mean it is pairing both streams.
        messages.append(topics.STIFFNESS_VALUES)
    if any(node.name == 'stiffness6_estimator' for node in started):
        messages.append(topics.POSE_SENSOR_POSE)  # the pose sensor, simulated or a tracker, publishing
    return {'wait_for_messages': messages,
            'wait_for_subscribers': [f'{topic}: {" ".join(names)}' for topic, names in readers.items()] or ['']}


def _argument(node: RigNode, param: str, arg: str, value: Any) -> str | int | float:
    """The value of parameter ``param`` from argument ``arg``: a string, or an integer for ``node.integers``, a
    float for ``node.floats`` ('max' = 0.0, the real-time factor's 'as fast as possible')."""
    if param in node.floats:
        text = str(value).strip().lower()
        try:
            return 0.0 if text == 'max' else float(text)
        except ValueError:
            raise RigError(f'{arg}:={value}: expected a number') from None
    if param not in node.integers:
        return str(value)
    try:
        return int(str(value))
    except ValueError:
        raise RigError(f'{arg}:={value}: expected an integer') from None


#: A program file with this section is a six-axis test (six_axis:=auto starts the 6x6 measurement for it).
SIX_AXIS_SECTION = 'stiffness6_estimator'


def _sections(path: str) -> set[str]:
    """The top-level keys (node sections) of a parameter file; none if it cannot be read (the node says why)."""
    import yaml
    try:
        with open(path) as f:
            data = yaml.safe_load(f)
    except (OSError, yaml.YAMLError):
        return set()
    return set(data) if isinstance(data, dict) else set()


def is_six_axis_program(path: str | os.PathLike) -> bool:
    """The program file has a ``stiffness6_estimator`` section: the rig measures the 6×6 stiffness for it."""
    return SIX_AXIS_SECTION in _sections(str(path))


def exit_problem(process: str, returncode: int | None, shutting_down: bool) -> str:
    """Why the launch must stop when the node process ``process`` (launch's name for it, ``crane_model-1``, or the
    node's) ended with ``returncode`` ('' when it may end so): a node that ends on its own with a non-zero status
    (a bad parameter: 2; load_program giving up on the rig: 1; a crash: a negative signal number) leaves a rig that
    measures nothing, so the launch ends with it, naming it. Status 0 (load_program done with its program) and
    whatever happens once the launch is shutting down (Ctrl-C) are no failure, but the recorder's
    RECORDER_CUT_STATUS at any time: its recording was stopped from outside, so the session's bag is not the whole
    run, and the launch ends non-zero saying so."""
    name = process.rsplit('-', 1)[0] if process.rsplit('-', 1)[-1].isdigit() else process
    if name == 'session_recorder' and returncode == RECORDER_CUT_STATUS:
        return ('session_recorder exited with status 3: its recording was stopped from outside (a ~/stop call) before '
                "the run's end, so the session's bag is not the whole run (its log and the bag's session end name who "
                'stopped it)')
    if shutting_down or returncode is None or returncode == 0:
        return ''
    how = f'was killed by signal {-returncode}' if returncode < 0 else f'exited with status {returncode}'
    why = {'load_program': ': it gave up waiting for the rig (its last lines say what never came)'}.get(name, '')
    return (f'{name} {how}{why}: the rig cannot measure without it, so the launch stops (see {name}\'s output '
            'above)')


def check_file_sections(files: Mapping[str, str], roles: Iterable[str]) -> None:
    """RigError naming a parameter file of ``roles`` (of ``files``: role -> path) with a section that applies to no
    node of the rig (:data:`NODES`), and the closest node: its parameters would be read by none, silently. A file
    that cannot be read passes here: the node that reads it stops and says why."""
    import yaml
    names = [node.name for node in NODES]
    for path in dict.fromkeys(files[role] for role in roles):
        try:
            file = ParamFile.read(path)
        except (OSError, UnicodeDecodeError, yaml.YAMLError):
            continue
        try:
            check_sections(path, file.sections, names)
        except ConfigError as exc:
            raise RigError(str(exc)) from None


def rig_nodes(config_dir: str | os.PathLike, given: Mapping[str, str | bool] | None = None) -> list[NodeStart]:
    """The nodes the rig starts for the arguments ``given`` (the rest at their defaults), in start order; RigError
    for what cannot start as asked (an unknown argument, program or value, a missing file, a file section that
    applies to no node of the rig)."""
    values = argument_values(config_dir, given)
    if values['transport'] not in TRANSPORTS:
        raise RigError(f"transport {values['transport']!r}: expected one of {', '.join(TRANSPORTS)}")
    if values['machine'] not in ('all', *MACHINES):
        raise RigError(f"machine {values['machine']!r}: expected one of all, {', '.join(MACHINES)}")
    files = config_files(config_dir, values)
    six_axis_program = is_six_axis_program(files['program'])
    if str(values['six_axis']).strip().lower() == 'auto':
        values['six_axis'] = 'true' if six_axis_program else 'false'
    sim_time = flag(values['use_sim_time'])
    if sim_time and values['transport'] != 'sim':
        raise RigError('use_sim_time:=true runs the simulated sensors only (transport:=sim): the drivers and their '
                       'device protocols keep wall-clock time')
    started = [node for node in NODES if (node.condition is None or flag(values[node.condition]))
               and all(str(values[arg]) == value for arg, value in node.when)]
    check_file_sections(files, {role for node in started for role in node.files
                                if role != 'drivers' or values['transport'] == 'drivers'})

    def clock(node: RigNode) -> dict[str, Any]:
        """Simulated time: every node follows /clock; the clock source waits for the participants started."""
        if not sim_time:
            return {}
        if node.name == 'sim_clock':
            return {'participants': [n.name for n in started if n.sim_stage is not None]}
        return {'use_sim_time': True}
    # load_program waits for the whole rig, the other machine's nodes too.
    return [NodeStart(node.name, node.executable,
                      tuple(files[f] for f in node.files if f != 'drivers' or values['transport'] == 'drivers'),
                      {**{param: _argument(node, param, arg, values[arg]) for param, arg in node.arguments.items()},
                       **(readiness(started) if node.runs_program else {}), **clock(node),
                       **({node.six_axis_parameter: six_axis_program} if node.six_axis_parameter else {})},
                      node.remappings, node.runs_program, node.machine)
            for node in started if values['machine'] in ('all', node.machine)]
