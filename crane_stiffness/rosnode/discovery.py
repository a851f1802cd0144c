"""Quicker DDS discovery when every node of the rig starts at once (Fast DDS, the default RMW).

A Fast DDS participant announces itself to the others 5 times, 0.1 s apart, when it starts, then once every 3 s.
``ros2 launch`` starts the rig's eight processes at the same instant on a machine with two cores: each spends a
second or more importing rclpy and numpy before its participant exists, so a participant's five announcements are
often over before a peer listens, and the two find each other only at the next periodic one, up to 3 s later (the
launch-to-program-start time came out 2.3 s or 5.5 s on the same machine). With the profile of
``fastdds_discovery.xml`` (the default participant profile: 30 announcements 0.1 s apart, nothing else changed) a
participant keeps announcing for the 3 s the others may need to come up.

:func:`use_quick_discovery` points Fast DDS at that profile through the environment of this process (before rclpy
creates a participant) unless a profile file is already chosen (``FASTRTPS_DEFAULT_PROFILES_FILE`` or
``FASTDDS_DEFAULT_PROFILES_FILE`` set) or another RMW is; each node calls it first (crane_stiffness.rosnode.entry), as
do the
demo and the start-up benchmark for their observers. Only the node processes' own environment changes.
"""
from __future__ import annotations

import os
from pathlib import Path
from typing import MutableMapping

#: The Fast DDS XML profile file (package data).
PROFILE = Path(__file__).with_name('fastdds_discovery.xml')
PROFILE_VARIABLES = ('FASTRTPS_DEFAULT_PROFILES_FILE', 'FASTDDS_DEFAULT_PROFILES_FILE')


def use_quick_discovery(environ: MutableMapping[str, str] | None = None) -> bool:
    """Set FASTRTPS_DEFAULT_PROFILES_FILE to :data:`PROFILE` in ``environ`` (default: this process's) when the RMW is
    Fast DDS and no profile file is chosen; True if it was set."""
    env = os.environ if environ is None else environ
    rmw = env.get('RMW_IMPLEMENTATION', 'rmw_fastrtps_cpp') or 'rmw_fastrtps_cpp'
    if not rmw.startswith('rmw_fastrtps') or any(env.get(v) for v in PROFILE_VARIABLES) or not PROFILE.is_file():
        return False
    env['FASTRTPS_DEFAULT_PROFILES_FILE'] = str(PROFILE)
    return True
