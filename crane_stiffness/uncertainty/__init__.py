"""Measurement uncertainty as the GUM states it: no ROS, no nodes; reads model/ and params/ only.

- :mod:`.inputs` — an input quantity as a certificate states it (U and k, or a half-width and a distribution), its
  standard uncertainty, its draws; the flat form of parameter files.
- :mod:`.budget` — the law of propagation (JCGM 100 5.1.2, 5.2.2), the budget, Welch–Satterthwaite, k, U:
  :func:`~.budget.propagate` → :class:`~.budget.UncertaintyResult`.
- :mod:`.montecarlo` — JCGM 101 Monte Carlo (adaptive), the GUM's validation, the vector form of JCGM 102.
- :mod:`.agreement` — E_n of a measured value against a reference (ISO 13528).
- :mod:`.crane_inputs` — the crane's uncertain inputs, their defaults and their file.
- :mod:`.prediction` — the model's stiffness prediction with its uncertainty and budget.

See docs/uncertainty.md.
"""
