"""The physics of the six-wire crane: pure numpy/numba, no ROS.

- :mod:`.geometry` — triangles, wires (the wire model lives here), weight, the lab-model preset.
- :mod:`.equilibrium` — the nonlinear static balance with slack wires; single, warm-started, path and batch solves.
- :mod:`.stiffness` — exact tangent stiffness, the paper's eq. (18), K0, Kw, K_j and stiffness along a direction.
- :mod:`.rotation` — the paper's z–x–y angles and conversions.
"""
from crane_stiffness.model.equilibrium import (BatchEquilibrium, Equilibrium, as_load, net_wrench, rest_pose,
                                               solve_batch, solve_equilibrium, solve_path, wrench_jacobian)
from crane_stiffness.model.errors import ConvergenceError, GeometryError, ModelError, NoEquilibriumError
from crane_stiffness.model.geometry import (WIRE_NAMES, CraneGeometry, lab_model, rest_wire_length)
from crane_stiffness.model.rotation import euler_zxy_to_matrix, matrix_to_euler_zxy
from crane_stiffness.model.stiffness import (AXES, PaperCoefficients, axis_index, axis_stiffness, compliance,
                                             directional_stiffness, elastic_stiffness, loaded_height,
                                             paper_coefficients, paper_stiffness, pendulum_stiffness,
                                             single_wire_pendulum_stiffness, tangent_stiffness)

__all__ = [
    'AXES', 'BatchEquilibrium', 'ConvergenceError', 'CraneGeometry', 'Equilibrium', 'GeometryError', 'ModelError',
    'NoEquilibriumError', 'PaperCoefficients', 'WIRE_NAMES', 'as_load', 'axis_index', 'axis_stiffness', 'compliance',
    'directional_stiffness', 'elastic_stiffness', 'euler_zxy_to_matrix', 'lab_model', 'loaded_height',
    'matrix_to_euler_zxy', 'net_wrench', 'paper_coefficients', 'paper_stiffness', 'pendulum_stiffness',
    'rest_pose', 'rest_wire_length', 'single_wire_pendulum_stiffness', 'solve_batch', 'solve_equilibrium',
    'solve_path', 'tangent_stiffness', 'wrench_jacobian',
]
