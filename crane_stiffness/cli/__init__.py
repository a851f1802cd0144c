"""The ``crane-stiffness`` command line: a thin layer over the package's pure rooms, no ROS needed.

- ``main.py``: the parser and :func:`~crane_stiffness.cli.main.main` (the console script; ``python -m
  crane_stiffness.cli`` runs the same); the subcommands ``solve``, ``stiffness`` and ``sweep`` live here, the others
  in the room whose work they do and are added to the parser from there: ``analyze``, ``compare``, ``recover``
  (``analysis/session_cli.py``), ``campaign`` and ``calibrate`` (``campaign/cli.py``), ``workspace``
  (``design/cli.py``), ``full6 design`` (``full6/cli.py``).
- ``geometry_args.py``: the geometry flags every command shares (``--config`` and the per-field flags).
- ``exit_codes.py``: the exit codes (0 ok, 2 bad input, 3 no equilibrium, 4 solver gave up, ...) and how an error
  becomes one, with one line on stderr naming the value and the rule.
"""
