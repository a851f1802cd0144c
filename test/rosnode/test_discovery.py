"""The nodes' Fast DDS discovery profile (crane_stiffness.rosnode.discovery): chosen only when nothing else is."""
from __future__ import annotations

import xml.etree.ElementTree as ET

from crane_stiffness.rosnode import discovery


def test_profile_is_a_default_participant_profile_with_longer_initial_announcements():
    ns = {'f': 'http://www.eprosima.com/XMLSchemas/fastRTPS_Profiles'}
    root = ET.parse(discovery.PROFILE).getroot()
    participant = root.find('f:participant', ns)
    assert participant is not None and participant.get('is_default_profile') == 'true'
    announcements = participant.find('f:rtps/f:builtin/f:discovery_config/f:initialAnnouncements', ns)
    assert announcements is not None
    count = int(announcements.findtext('f:count', namespaces=ns))
    period_s = int(announcements.findtext('f:period/f:nanosec', namespaces=ns)) * 1e-9
    assert count * period_s >= 3.0  # as long as the periodic announcement's period


def test_profile_is_set_only_for_fast_dds_and_when_no_profile_file_is_chosen():
    env: dict[str, str] = {}
    assert discovery.use_quick_discovery(env) and env['FASTRTPS_DEFAULT_PROFILES_FILE'] == str(discovery.PROFILE)
    env = {'RMW_IMPLEMENTATION': 'rmw_fastrtps_cpp'}
    assert discovery.use_quick_discovery(env)
    for chosen in ({'FASTRTPS_DEFAULT_PROFILES_FILE': '/etc/mine.xml'}, {'FASTDDS_DEFAULT_PROFILES_FILE': '/x.xml'},
                   {'RMW_IMPLEMENTATION': 'rmw_cyclonedds_cpp'}):
        env = dict(chosen)
        assert not discovery.use_quick_discovery(env)
        assert env == chosen
