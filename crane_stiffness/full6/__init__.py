"""The whole 6×6 stiffness matrix from one test: designed multi-axis load programs and the identification of the
compliance C and the stiffness K = C⁻¹ from (wrench, pose deflection) pairs. Pure numpy/scipy, no ROS.

- :mod:`.reference` — what a result is compared with: the exact tangent at the rest pose, the paper's eq. (18),
  where K2 sits.
- :mod:`.deflection` — a pose (position, rotation) as the deflection 6-vector the fit takes.
- :mod:`.lvdt_array` — the deflection 6-vector from n >= 6 LVDTs touching the platform, with its covariance, and
  the refusal of an arrangement that cannot determine it.
- :mod:`.admissible` — the loads a program may hold: the slack factor of a wrench, the safety-factor rule and the
  refusal that names the step, the direction and the wire; the admissible polytope of a fold-over design.
- :mod:`.design` — the D-optimal program and the naive one-axis-at-a-time program, with their predicted precision.
- :mod:`.program` — a design as a load program (config/program_full6.yaml), and the held steps of a program.
- :mod:`.statistics` — the sufficient statistics of labelled pairs, vectorised and streaming.
- :mod:`.identify` — the fit with errors in both variables, the intervals, the status.
- :mod:`.live_uncertainty` — the live fit's expanded uncertainty U of K and K2 (the law of propagation on its step
  means and the sensors' declared calibrations).
- :mod:`.precision` — the predicted interval widths of a program, and two programs side by side.
- :mod:`.cli` — ``crane-stiffness full6 design``, the command-line layer.
- :mod:`.errors` — the package's exceptions.

Docs: docs/full_stiffness.md.
"""
