"""The Fast DDS profile the nodes load (hexapod_vibration.ros.fastdds_profile)."""

from __future__ import annotations

import os
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest

from hexapod_vibration.paths import config_path
from hexapod_vibration.ros.dds_transport import PROFILES_VARIABLES
from hexapod_vibration.ros.fastdds_profile import (
    PROFILES_FILE,
    profile_variables,
    use_package_profile,
)

NS = {"p": "http://www.eprosima.com/XMLSchemas/fastRTPS_Profiles"}


def writer_profiles() -> dict[str, ET.Element]:
    """The data_writer profiles of the package's file, by profile (topic) name."""
    root = ET.parse(config_path(PROFILES_FILE)).getroot()
    assert root.tag == f"{{{NS['p']}}}profiles"
    return {w.get("profile_name"): w for w in root.findall("p:data_writer", NS)}


def test_the_package_file_by_default_a_users_file_or_another_rmw_left_alone():
    profiles = Path("/share/config/fastdds_profiles.xml")
    for env in ({}, {"RMW_IMPLEMENTATION": "rmw_fastrtps_dynamic_cpp"},
                {PROFILES_VARIABLES[0]: ""}):
        assert profile_variables(env, profiles) == {PROFILES_VARIABLES[0]: str(profiles)}
    for env in ({PROFILES_VARIABLES[0]: "/mine.xml"}, {PROFILES_VARIABLES[1]: "/mine.xml"},
                {"RMW_IMPLEMENTATION": "rmw_cyclonedds_cpp"}):
        assert profile_variables(env, profiles) == {}, env


def test_a_node_process_gets_the_package_file_unless_the_user_has_one(monkeypatch):
    for name in (*PROFILES_VARIABLES, "RMW_IMPLEMENTATION"):
        monkeypatch.setenv(name, "")      # recorded, so the teardown restores this worker's
        monkeypatch.delenv(name)          # environment whatever use_package_profile sets
    use_package_profile()
    assert os.environ[PROFILES_VARIABLES[0]] == str(config_path(PROFILES_FILE))
    monkeypatch.setenv(PROFILES_VARIABLES[0], "/mine.xml")
    use_package_profile()
    assert os.environ[PROFILES_VARIABLES[0]] == "/mine.xml"


@pytest.mark.parametrize("topic", sorted(writer_profiles()))
def test_each_profile_sets_a_100_ms_heartbeat_and_nothing_else(topic):
    writer = writer_profiles()[topic]
    assert [child.tag.split("}")[1] for child in writer] == ["times"]
    times = writer.find("p:times", NS)
    assert [child.tag.split("}")[1] for child in times] == ["heartbeatPeriod"]
    period = times.find("p:heartbeatPeriod", NS)
    seconds = int(period.find("p:sec", NS).text) + int(period.find("p:nanosec", NS).text) * 1e-9
    assert seconds == pytest.approx(0.1)


def test_the_profile_names_every_writer_a_node_awaits_at_exit(ros_context):
    from hexapod_vibration.nodes.driver_outputs import DriverOutputs
    from hexapod_vibration.ros.matching import READERS_SUFFIX

    # The driver waits for its loop publishers' readers (DriverOutputs.readers), every
    # node for those of its /diagnostics (node_runner._flush_diagnostics).
    outputs = DriverOutputs(ros_context.create_node("outputs"), 1000.0, lambda: None)
    awaited = {key.removesuffix(READERS_SUFFIX) for key in outputs.readers.values()}
    assert set(writer_profiles()) == awaited | {"/diagnostics"}
