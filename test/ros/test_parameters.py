"""parameters: descriptors carry ranges, units and read-only flags that rclpy enforces."""

import pytest
from rclpy.parameter import Parameter

from hexapod_vibration.ros import parameters as p


@pytest.fixture
def node(ros_context):
    return ros_context.create_node("parameter_test")


def test_float_range_is_enforced(node):
    assert p.declare_float(node, "mu", 0.01, "convergence rate (1/sample)", 0.0, 0.5) == 0.01
    descriptor = node.describe_parameter("mu")
    assert descriptor.description == "convergence rate (1/sample)"
    assert descriptor.floating_point_range[0].to_value == 0.5
    assert not node.set_parameters([Parameter("mu", value=0.6)])[0].successful
    assert node.set_parameters([Parameter("mu", value=0.2)])[0].successful
    assert node.get_parameter("mu").value == 0.2


def test_open_ended_float_range(node):
    p.declare_float(node, "gap_m", 1e-3, "gap (m)", min_value=0.0)
    assert not node.set_parameters([Parameter("gap_m", value=-1.0)])[0].successful
    assert node.set_parameters([Parameter("gap_m", value=1e9)])[0].successful


def test_int_bool_string(node):
    assert p.declare_int(node, "depth", 10, "queue depth (messages)", 1, 100) == 10
    assert not node.set_parameters([Parameter("depth", value=0)])[0].successful
    assert p.declare_bool(node, "enabled", False, "control on") is False
    assert p.declare_string(node, "mode", "lockstep", "loop mode", ("lockstep", "realtime")) == (
        "lockstep"
    )
    assert "realtime" in node.describe_parameter("mode").additional_constraints


def test_read_only(node):
    p.declare_float(node, "fs_hz", 1000.0, "sample rate (Hz)", read_only=True)
    result = node.set_parameters([Parameter("fs_hz", value=500.0)])[0]
    assert not result.successful and "read-only" in result.reason


def test_float_array(node):
    assert p.declare_float_array(node, "tones_hz", [40.0, 80.0], "tones (Hz)", 0.0, 500.0) == [
        40.0,
        80.0,
    ]
    assert "every element in [0, 500]" in node.describe_parameter("tones_hz").additional_constraints
    assert p.declare_float_array(node, "empty_hz", [], "tones (Hz)") == []
    assert node.set_parameters([Parameter("empty_hz", value=[1.0])])[0].successful


def test_string_choice_rejected_at_start(ros_context):
    node = ros_context.create_node(
        "parameter_override_test", parameter_overrides=[Parameter("storage", value="zip")]
    )
    with pytest.raises(ValueError, match="storage = 'zip' is not one of: mcap, sqlite3"):
        p.declare_string(node, "storage", "mcap", "storage", choices=("mcap", "sqlite3"))


def test_checks_and_results():
    assert (
        p.check_float_array("f", [1.0, 600.0], 0.0, 500.0) == "f[1] = 600 is above the maximum 500"
    )
    assert p.check_float_array("f", [-1.0], 0.0, None) == "f[0] = -1 is below the minimum 0"
    assert p.check_float_array("f", [1.0], 0.0, 500.0) == ""
    assert p.check_choice("m", "x", ("a", "b")) == "m = 'x' is not one of: a, b"
    assert p.accept().successful
    rejected = p.reject("mu above the stability bound 0.4")
    assert not rejected.successful and rejected.reason == "mu above the stability bound 0.4"
