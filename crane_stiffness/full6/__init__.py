"""The whole 6×6 stiffness matrix from one test: designed multi-axis load programs and the identification of the
compliance C and the stiffness K = C⁻¹ from (wrench, pose deflection) pairs. Pure numpy/scipy, no ROS.

- :mod:`.reference` — what a result is compared with: the exact tangent at the rest pose, the paper's eq. (18),
  where K2 sits.
- :mod:`.deflection` — a pose (position, rotation) as the deflection 6-vector the fit takes.
- :mod:`.errors` — the package's exceptions.

Docs: docs/full_stiffness.md.
"""
