"""``python -m crane_stiffness.cli``: the ``crane-stiffness`` command."""
import sys

from crane_stiffness.cli.main import main

sys.exit(main())
