"""The exit codes of the ``crane-stiffness`` command line and the one way its commands turn errors into them.

0 ok; 1 a session failed on the rig; 2 bad input (named on stderr); 3 no equilibrium for the load; 4 the solver gave
<<<<<<< HEAD
up; 5 ``campaign run``: every session ran, but one or more is NOT OK or its bag was cut short (named on stderr with
the causes); 130 interrupted.
=======
up; 5 ``analyze``'s verdict is NOT OK (a fit that is not a stiffness, the fitted axis not the loaded one, or a branch
far from the model: the reasons printed and in the report); 130 interrupted.
>>>>>>> mcana
"""
from __future__ import annotations

import sys
from typing import Callable, Sequence

EXIT_OK = 0
EXIT_FAILED = 1
EXIT_USAGE = 2
EXIT_NO_EQUILIBRIUM = 3
EXIT_SOLVER = 4
#: ``analyze`` ran and wrote everything, and its verdict is NOT OK (crane_stiffness.analysis.verdict).
EXIT_NOT_OK = 5
#: ``campaign run``: a session's verdict is NOT OK (the analysis' problems, the estimator's status) or its bag is not
#: the whole run (cut short); stderr names each such session and why.
EXIT_SESSION_NOT_OK = 5
EXIT_INTERRUPTED = 130

#: (exception classes, exit code, stderr message with ``{exc}`` for the exception), first match wins.
ExitRule = tuple['type[BaseException] | tuple[type[BaseException], ...]', int, str]


def run_to_exit_code(run: Callable[[], int], rules: Sequence[ExitRule]) -> int:
    """``run()``; an exception of a rule's classes instead prints ``crane-stiffness: <message>`` on stderr and
    returns the rule's code. Any other exception propagates."""
    try:
        return run()
    except BaseException as exc:
        for classes, code, message in rules:
            if isinstance(exc, classes):
                print('crane-stiffness: ' + message.format(exc=exc), file=sys.stderr)
                return code
        raise
