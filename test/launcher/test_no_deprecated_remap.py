"""The launchers' own rclpy contexts never read the process's command line: ``crane-stiffness campaign run --rig-arg
transport:=drivers`` has a ``NAME:=VALUE`` in sys.argv, which rcl takes for a remap rule in the deprecated syntax and
warns about on every context (once per session and look at a domain's graph)."""
from __future__ import annotations

import subprocess
import sys

import pytest

from helpers import PATIENCE_S, REPO

pytestmark = pytest.mark.ros

BODY = '''
import sys
sys.argv = ['crane-stiffness', 'campaign', 'run', 'c.yaml', '--rig-arg', 'transport:=drivers']
from crane_stiffness.launcher.domains import claim_domain
from crane_stiffness.launcher.rig_host import RigHost
claim = claim_domain({domain}, 'test', look_s=0.5)
claim.release()
host = RigHost({domain})
host.close()
print('done')
'''


def test_a_name_value_on_the_command_line_gives_no_deprecated_remap_warning(ros_domain):
    out = subprocess.run([sys.executable, '-c', BODY.format(domain=ros_domain)], cwd=REPO, capture_output=True,
                         text=True, timeout=PATIENCE_S)
    assert out.returncode == 0 and 'done' in out.stdout, out.stdout + out.stderr
    assert 'deprecated' not in out.stderr + out.stdout, out.stderr
