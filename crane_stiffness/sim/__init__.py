"""Simulation of the rig's sensors and load programs: pure Python/numpy, no ROS.

- :mod:`.sensors` — six-axis load cell and LVDT models with noise, drift, cross-talk, quantization and saturation.
- :mod:`.pose_sensor` — a motion-capture pose sensor with position and orientation noise and bias.
- :mod:`.calibration` — a sensor's calibration as its certificate states it (the ``calibration.*`` parameters).
- :mod:`.truth` — a simulated sensor's true calibration errors: perfect, given, or drawn from its calibration.
- :mod:`.noise` — coloured noise (AR(1), 1/f, a mains line) and random-walk zero drift.
- :mod:`.program` — load programs (ramps, holds, steps) from ROS-parameter-style parallel arrays or YAML files.
- :mod:`.errors` — the package's exceptions.
"""
from crane_stiffness.sim.errors import ParameterError, ProgramFileError, SimError
from crane_stiffness.sim.program import (AXES, KINDS, PARAM_NAMES, HoldInterval, LoadProgram, Phase, ProgramState,
                                         Segment, load_program_file)
from crane_stiffness.sim.pose_sensor import PoseSensorModel
from crane_stiffness.sim.sensors import LoadCellModel, LvdtModel

__all__ = [
    'AXES', 'KINDS', 'PARAM_NAMES', 'HoldInterval', 'LoadCellModel', 'LoadProgram', 'LvdtModel', 'ParameterError',
    'Phase', 'PoseSensorModel', 'ProgramFileError', 'ProgramState', 'Segment', 'SimError', 'load_program_file',
]
