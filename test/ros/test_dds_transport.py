"""The transport of a realtime graph's processes (hexapod_vibration.ros.dds_transport)."""

from hexapod_vibration.ros.dds_transport import (
    REALTIME_TRANSPORTS,
    TRANSPORT_VARIABLE,
    realtime_transport_env,
)


def test_udp_only_by_default_and_the_environment_is_not_changed():
    given = {"ROS_DOMAIN_ID": "7"}
    env, note = realtime_transport_env(given)
    assert env == {"ROS_DOMAIN_ID": "7", TRANSPORT_VARIABLE: REALTIME_TRANSPORTS}
    assert note == "" and given == {"ROS_DOMAIN_ID": "7"}


def test_a_users_choice_of_transports_or_of_another_rmw_is_kept():
    for chosen in ({TRANSPORT_VARIABLE: "SHM"}, {"FASTRTPS_DEFAULT_PROFILES_FILE": "/x.xml"},
                   {"FASTDDS_DEFAULT_PROFILES_FILE": "/y.xml"},
                   {"RMW_IMPLEMENTATION": "rmw_cyclonedds_cpp"}):
        assert realtime_transport_env(chosen) == (chosen, "")
    env, _ = realtime_transport_env({"RMW_IMPLEMENTATION": "rmw_fastrtps_dynamic_cpp"})
    assert env[TRANSPORT_VARIABLE] == REALTIME_TRANSPORTS


def test_localhost_only_discovery_is_said_in_one_line_and_nothing_is_set():
    for given in ({"ROS_AUTOMATIC_DISCOVERY_RANGE": "localhost"}, {"ROS_LOCALHOST_ONLY": "1"}):
        env, note = realtime_transport_env(given)
        assert env == given
        assert "shared-memory" in note and "\n" not in note
    env, note = realtime_transport_env({"ROS_AUTOMATIC_DISCOVERY_RANGE": "SUBNET"})
    assert env[TRANSPORT_VARIABLE] == REALTIME_TRANSPORTS and note == ""
