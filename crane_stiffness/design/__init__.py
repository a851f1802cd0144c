"""Design questions over the crane's workspace: pure numpy/numba, no ROS.

- :mod:`.pose` — at a pose: the inverse problem, the equilibrium, the tangent stiffness split into its force part
  (N/m) and its moment part (N·m/rad), the tensions.
- :mod:`.margins` — the slack margin per load direction (continuation on the nonlinear model).
- :mod:`.maps` — any two of (x, y, h, W, a, b, payload offset) on a grid: stiffness, margin, tension; resumable.
- :mod:`.figures` — heatmaps with contours, the polar and sphere plots of the margins.
- :mod:`.cli` — the ``crane-stiffness workspace`` subcommand.
"""
