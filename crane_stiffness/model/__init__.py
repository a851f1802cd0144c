"""The physics of the six-wire crane: pure numpy/numba, no ROS.

- :mod:`.geometry` — triangles, wires (the wire model lives here), weight, the lab-model preset.
- :mod:`.equilibrium` — the nonlinear static balance with slack wires; single, warm-started, path and batch solves.
- :mod:`.stiffness` — exact tangent stiffness, the paper's eq. (18), K0, Kw, K_j and stiffness along a direction.
- :mod:`.rotation` — the paper's z–x–y angles and conversions.
"""
import importlib
from typing import TYPE_CHECKING

if TYPE_CHECKING:  # the names for type checkers; at run time __getattr__ (below) imports each module on first use
    # Re-exported through the __all__ built below from _EXPORTS, which linters cannot follow: hence the F401 noqa.
    from .equilibrium import (  # noqa: F401
        BatchEquilibrium, Equilibrium, as_load, net_wrench, rest_pose, solve_batch, solve_equilibrium, solve_path,
        wrench_jacobian)
    from .errors import ConvergenceError, GeometryError, ModelError, NoEquilibriumError  # noqa: F401
    from .geometry import WIRE_NAMES, CraneGeometry, lab_model, rest_wire_length  # noqa: F401
    from .rotation import euler_zxy_to_matrix, matrix_to_euler_zxy  # noqa: F401
    from .stiffness import (  # noqa: F401
        AXES, PaperCoefficients, axis_index, axis_stiffness, compliance, directional_stiffness, elastic_stiffness,
        loaded_height, paper_coefficients, paper_stiffness, pendulum_stiffness, single_wire_pendulum_stiffness,
        tangent_stiffness)

#: The public names and the module of each. Imported on first use: importing .geometry alone (params.geometry,
#: so every node) must not import .equilibrium and numba (~0.5 s of CPU in each node process at start).
_EXPORTS = {
    'equilibrium': ('BatchEquilibrium', 'Equilibrium', 'as_load', 'net_wrench', 'rest_pose', 'solve_batch',
                    'solve_equilibrium', 'solve_path', 'wrench_jacobian'),
    'errors': ('ConvergenceError', 'GeometryError', 'ModelError', 'NoEquilibriumError'),
    'geometry': ('WIRE_NAMES', 'CraneGeometry', 'lab_model', 'rest_wire_length'),
    'rotation': ('euler_zxy_to_matrix', 'matrix_to_euler_zxy'),
    'stiffness': ('AXES', 'PaperCoefficients', 'axis_index', 'axis_stiffness', 'compliance', 'directional_stiffness',
                  'elastic_stiffness', 'loaded_height', 'paper_coefficients', 'paper_stiffness', 'pendulum_stiffness',
                  'single_wire_pendulum_stiffness', 'tangent_stiffness'),
}
_WHERE = {name: module for module, names in _EXPORTS.items() for name in names}
__all__ = sorted(_WHERE)


def __getattr__(name: str):
    if name in _WHERE:
        value = getattr(importlib.import_module(f'crane_stiffness.model.{_WHERE[name]}'), name)
        globals()[name] = value
        return value
    raise AttributeError(f'module {__name__!r} has no attribute {name!r}')
