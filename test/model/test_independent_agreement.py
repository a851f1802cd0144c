"""The ``crane-stiffness`` CLI against an independent reference implementation (``independent_crane.py``).

The reference was written from the paper and its corrections (docs/physics.md) without reading, importing or
copying anything from the ``crane_stiffness`` package. test_independent_reference.py checks the reference on its own
(finite differences, an energy formulation, the closed form of eq. 18); the ``test_cli_*`` tests here run the CLI and
compare its JSON with the reference: every case through the CLI's ``main`` in this process (argv in, exit code,
stdout and stderr out: seconds for all of them, so the pure tests run alone quickly), and a few through the installed
console script in a subprocess, whose output must be the same to the byte.

Done-when (from the issue): pose within 1e-9 m and 1e-9 rad, tensions within 1e-6 relative, stiffness within
1e-6 relative to the largest entry, on random geometries and loads with slack and rotated cases included.

Assumptions about the CLI contract (documented here because the contract leaves them open)
--------------------------------------------------------------------------------------
* ``wire_lengths`` are the geometric distances |l_i| between the attachment points (also for slack wires).
* ``slack[i]`` is ``|l_i| < l0_i``; a slack wire's tension is exactly 0.
* With ``--wire-diameter/--youngs-modulus`` each wire's stiffness is k_i = E*pi*d^2/4 / l0_i with its own
  unstretched length l0_i = l0 + d_i (a longer wire of the same cross-section is softer; with no offsets this is
  the paper's single k = E A / l0). ``--wire-stiffness`` gives the same k to every wire.
* ``tangent`` is -dw/dx of the NET wrench (wires + weight + external load), rotations perturbed in the fixed
  frame, F and M fixed in space.  The external force therefore contributes -[F]x[Q p]x to the moment block when
  a ``--load-point`` p is given (the moment arm of F turns with the platform); M contributes nothing.
* ``paper`` is eq. (18) as a formula of a, b, h, k and W (h_w from the implicit balance of docs/physics.md); it
  ignores ``--com``, ``--load-point`` and ``--length-offsets``.
* ``euler_zxy`` angles are compared modulo 2*pi (all cases here stay far from gimbal lock).
* ``wire_lengths`` are compared to 3e-9 m: a pose error of 1e-9 per component moves an attachment point by up to
  about that much.
* Numbers are passed in positional notation (``numpy.format_float_positional``, exact round trip), because
  Python 3.11's argparse takes an argument such as ``-1.5e-05`` for an option flag.
* The CLI is ``crane_stiffness.cli.main.main`` and the console script in ``sysconfig.get_path('scripts')`` of the
  interpreter running the tests, which calls it; the tests FAIL (not skip) when it is missing, so they cannot pass
  vacuously.
"""

from __future__ import annotations

import io
import json
import os
import shutil
import subprocess
import sys
import sysconfig
from contextlib import redirect_stderr, redirect_stdout

import numpy as np
import pytest

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))  # test/: independent_crane.py
import independent_crane as ic  # noqa: E402

from helpers.independent_cases import (  # noqa: E402
    CASES, CASE_NAMES, LENGTH_TOL_M, NO_EQUILIBRIUM, POSE_TOL_M, POSE_TOL_RAD, STIFFNESS_RTOL, TENSION_RTOL, reference,
)


# ----------------------------------------------------------------------------------------------------------
# The CLI against the reference
# ----------------------------------------------------------------------------------------------------------

def cli_path() -> str:
    path = os.path.join(sysconfig.get_path("scripts"), "crane-stiffness")
    if os.path.exists(path):
        return path
    found = shutil.which("crane-stiffness")
    if found:
        return found
    pytest.fail(f"console script crane-stiffness not found at {path} or on PATH")


def run_cli(args: list[str]) -> subprocess.CompletedProcess:
    """The installed console script in a subprocess."""
    return subprocess.run([cli_path(), *args], capture_output=True, text=True, timeout=120,
                          env=dict(os.environ))


def run_cli_main(args: list[str]) -> subprocess.CompletedProcess:
    """``crane_stiffness.cli.main.main`` in this process, as the console script calls it: exit code, stdout, stderr."""
    from crane_stiffness.cli.main import main
    out, err = io.StringIO(), io.StringIO()
    with redirect_stdout(out), redirect_stderr(err):
        try:
            code = main(args)
        except SystemExit as exc:  # argparse's usage errors
            code = exc.code if isinstance(exc.code, int) else 2
    return subprocess.CompletedProcess(["crane-stiffness", *args], code, out.getvalue(), err.getvalue())


def _jobs() -> dict[tuple[str, str], list[str]]:
    jobs = {(name, cmd): CASES[name].cli_args(cmd) for name in CASE_NAMES for cmd in ("solve", "stiffness")}
    jobs[("upward_force", "solve")] = NO_EQUILIBRIUM.cli_args("solve")
    jobs[("upward_force", "stiffness")] = NO_EQUILIBRIUM.cli_args("stiffness")
    return jobs


#: The calls also run through the console script: one case of each command, and the failing load.
SUBPROCESS_JOBS = [(CASE_NAMES[0], "solve"), (CASE_NAMES[-1], "stiffness"), ("upward_force", "solve")]


@pytest.fixture(scope="module")
def cli_outputs():
    """Every CLI call, through ``main`` in this process (one case per call)."""
    cli_path()
    return {key: run_cli_main(args) for key, args in _jobs().items()}


@pytest.mark.parametrize("key", SUBPROCESS_JOBS, ids=["/".join(k) for k in SUBPROCESS_JOBS])
def test_the_console_script_prints_what_main_prints(cli_outputs, key):
    """The installed executable gives exactly what ``main`` gave in this process: the in-process runs stand for it."""
    args = _jobs()[key]
    proc = run_cli(args)
    assert (proc.returncode, proc.stdout) == (cli_outputs[key].returncode, cli_outputs[key].stdout)
    assert proc.stderr.strip() == cli_outputs[key].stderr.strip()


def _json(proc: subprocess.CompletedProcess, args) -> dict:
    assert proc.returncode == 0, f"crane-stiffness {' '.join(args)}\nexit {proc.returncode}\n{proc.stderr}"
    try:
        return json.loads(proc.stdout)
    except json.JSONDecodeError as exc:
        raise AssertionError(f"stdout is not one JSON document: {exc}\n{proc.stdout[:2000]}") from exc


def _wrap(d):
    return (np.asarray(d) + np.pi) % (2 * np.pi) - np.pi


@pytest.mark.parametrize("name", CASE_NAMES)
def test_cli_solve_matches_reference(cli_outputs, name):
    case = CASES[name]
    ref = reference(name)
    out = _json(cli_outputs[(name, "solve")], case.cli_args("solve"))
    for key in ("converged", "displacement", "rotation", "euler_zxy", "wire_lengths", "wire_tensions", "slack"):
        assert key in out, f"missing key {key}"
    assert out["converged"] is True
    u = np.asarray(out["displacement"], dtype=float)
    Q = np.asarray(out["rotation"], dtype=float)
    eul = np.asarray(out["euler_zxy"], dtype=float)
    L = np.asarray(out["wire_lengths"], dtype=float)
    t = np.asarray(out["wire_tensions"], dtype=float)
    slack = np.asarray(out["slack"])
    assert u.shape == (3,) and Q.shape == (3, 3) and eul.shape == (3,)
    assert L.shape == (6,) and t.shape == (6,) and slack.shape == (6,)
    assert slack.dtype == bool, f"slack must be booleans, got {out['slack']}"

    assert np.abs(u - ref.displacement).max() <= POSE_TOL_M, (u, ref.displacement)
    # rotation: matrix entries and the angle of Q_cli Q_ref^T
    assert np.abs(Q - ref.rotation).max() <= POSE_TOL_RAD, (Q, ref.rotation)
    R = Q @ ref.rotation.T
    assert np.linalg.norm([R[2, 1] - R[1, 2], R[0, 2] - R[2, 0], R[1, 0] - R[0, 1]]) / 2 <= POSE_TOL_RAD
    assert np.abs(_wrap(eul - ref.euler_zxy)).max() <= POSE_TOL_RAD, (eul, ref.euler_zxy)
    assert np.abs(L - ref.wire_lengths).max() <= LENGTH_TOL_M, (L, ref.wire_lengths)
    assert np.array_equal(slack, ref.slack), (slack, ref.slack)
    assert np.abs(t - ref.wire_tensions).max() <= TENSION_RTOL * ref.wire_tensions.max(), (t, ref.wire_tensions)
    assert np.all(t[slack] == 0)


@pytest.mark.parametrize("name", CASE_NAMES)
def test_cli_stiffness_matches_reference(cli_outputs, name):
    case = CASES[name]
    crane = case.crane()
    ref = reference(name)
    out = _json(cli_outputs[(name, "stiffness")], case.cli_args("stiffness"))
    assert "tangent" in out and "paper" in out
    K = np.asarray(out["tangent"], dtype=float)
    P = np.asarray(out["paper"], dtype=float)
    assert K.shape == (6, 6) and P.shape == (6, 6)
    K_ref = ic.tangent_stiffness(crane, ref.displacement, ref.rotation, case.force, case.load_point)
    P_ref = ic.paper_stiffness(crane.a, crane.b, crane.h, crane.k, crane.weight)
    err = np.abs(K - K_ref).max() / np.abs(K_ref).max()
    assert err <= STIFFNESS_RTOL, f"tangent off by {err:.3g} of max entry\n{K}\n{K_ref}"
    err = np.abs(P - P_ref).max() / np.abs(P_ref).max()
    assert err <= STIFFNESS_RTOL, f"paper off by {err:.3g} of max entry\n{P}\n{P_ref}"
    if name == "weight_only":
        assert np.abs(K - P).max() <= STIFFNESS_RTOL * np.abs(P).max()


@pytest.mark.parametrize("command", ["solve", "stiffness"])
def test_cli_no_equilibrium_exits_nonzero(cli_outputs, command):
    proc = cli_outputs[("upward_force", command)]
    assert proc.returncode != 0
    assert proc.stdout.strip() == ""
    assert proc.stderr.strip() != ""
    assert "Traceback" not in proc.stderr, proc.stderr
