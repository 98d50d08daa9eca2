"""Bring up the simulated hexapod and its controllers, optionally with the recorder.

    ros2 launch hexapod_vibration pph.launch.py
    ros2 launch hexapod_vibration pph.launch.py clock_mode:=realtime
    ros2 launch hexapod_vibration pph.launch.py params_file:=/path/to/my_pph.yaml
    ros2 launch hexapod_vibration pph.launch.py record:=true bag_path:=/tmp/pph_bag
    ros2 launch hexapod_vibration pph.launch.py composed:=true
    ros2 launch hexapod_vibration pph.launch.py clock_mode:=realtime realtime_priority:=50
    ros2 launch hexapod_vibration pph.launch.py clock_mode:=realtime command_delay_samples:=1
    ros2 launch hexapod_vibration pph.launch.py clock_mode:=realtime identification_analysis:=loop

Starts ``pph_driver``, ``notch_controller`` and ``pointing_controller`` (node names = the
executable names) with the parameters of ``config/pph.yaml`` from the package's share
directory (or ``params_file``); ``clock_mode`` overrides the driver's clock mode. With
``record:=true`` it also starts ``pph_recorder``, which writes the contract topics into
the bag directory ``bag_path`` (empty: ``rosbag2_<date>-<time>`` in the current directory).
With ``composed:=true`` the three nodes run in one process (``pph_graph``: same node names,
parameters and topics, intra-process delivery; see docs/performance.md).
``realtime_priority`` (1-98; 0 = off) runs the loop processes under SCHED_FIFO, refused at
start-up where the OS does not permit it; per-node CPUs (``cpu_affinity``) go in the params
file. ``command_delay_samples`` (default 2 in realtime, as ``experiment --realtime``, 0 in
lockstep) gives the controllers that many more periods to answer; the notch controller adds
it to its loop delay. ``identification_analysis`` (default ``process`` in realtime, as
``experiment --realtime``, ``loop`` in lockstep) is where the notch controller analyses a
finished identification: a worker process keeps the loop's deadline through it. In
realtime the nodes use Fast DDS's UDP transport only (``FASTDDS_BUILTIN_TRANSPORTS=UDPv4``)
unless the environment chose the transports: see docs/performance.md.
"""

import os

from ament_index_python.packages import get_package_share_directory
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument, SetEnvironmentVariable
from launch.conditions import IfCondition, UnlessCondition
from launch.substitutions import LaunchConfiguration, PythonExpression
from launch_ros.actions import Node
from launch_ros.parameter_descriptions import ParameterValue

from hexapod_vibration.ros.dds_transport import realtime_transport_variables

PACKAGE = "hexapod_vibration"
PARAMS_FILE = "pph.yaml"
REALTIME_COMMAND_DELAY_SAMPLES = 2
"""The default ``command_delay_samples`` in realtime (``experiment_setup``'s, measured)."""


def generate_launch_description() -> LaunchDescription:
    """The launch description: arguments, the three nodes and the optional recorder."""
    default_params = os.path.join(get_package_share_directory(PACKAGE), "config", PARAMS_FILE)
    params_file = LaunchConfiguration("params_file")
    clock_mode = LaunchConfiguration("clock_mode")
    record = LaunchConfiguration("record")
    bag_path = LaunchConfiguration("bag_path")
    composed = LaunchConfiguration("composed")
    priority = LaunchConfiguration("realtime_priority")
    command_delay = LaunchConfiguration("command_delay_samples")
    analysis = LaunchConfiguration("identification_analysis")
    arguments = [
        DeclareLaunchArgument(
            "params_file", default_value=default_params,
            description="ROS params file for pph_driver, notch_controller, pointing_controller"),
        DeclareLaunchArgument(
            "clock_mode", default_value="lockstep", choices=["lockstep", "realtime"],
            description="driver clock: lockstep (deterministic, as fast as the controllers "
                        "answer) or realtime (paced at 1 kHz wall clock)"),
        DeclareLaunchArgument(
            "record", default_value="false", choices=["true", "false"],
            description="also start pph_recorder (rosbag2 bag of the contract topics)"),
        DeclareLaunchArgument(
            "composed", default_value="false", choices=["true", "false"],
            description="run the driver and both controllers in one process (pph_graph)"),
        DeclareLaunchArgument(
            "realtime_priority", default_value="0",
            description="SCHED_FIFO priority (1-98) of the driver and controllers; 0: the "
                        "normal scheduler (overrides the params file)"),
        DeclareLaunchArgument(
            "command_delay_samples",
            default_value=PythonExpression([
                f"{REALTIME_COMMAND_DELAY_SAMPLES} if '", clock_mode, "' == 'realtime' else 0"]),
            description="samples between a sample and the command answering it, on the "
                        "driver and both controllers (0-10; default: 2 in realtime, 0 in "
                        "lockstep; overrides the params file)"),
        DeclareLaunchArgument(
            "identification_analysis",
            default_value=PythonExpression([
                "'process' if '", clock_mode, "' == 'realtime' else 'loop'"]),
            choices=["loop", "process"],
            description="where the notch controller analyses a finished identification: "
                        "loop (its loop's thread; default in lockstep) or process (a worker "
                        "process; default in realtime); separate processes only (composed: "
                        "the params file's)"),
        DeclareLaunchArgument(
            "bag_path", default_value="",
            description="bag directory of the recorder (must not exist); empty: "
                        "rosbag2_<date>-<time> in the current directory"),
    ]
    scheduling = {"realtime_priority": ParameterValue(priority, value_type=int),
                  "command_delay_samples": ParameterValue(command_delay, value_type=int)}
    controller_parameters = [params_file, scheduling]
    driver_parameters = [*controller_parameters,
                         {"clock_mode": ParameterValue(clock_mode, value_type=str)}]
    notch_parameters = [*controller_parameters,
                        {"identification_analysis": ParameterValue(analysis, value_type=str)}]
    separate = UnlessCondition(composed)
    realtime = IfCondition(PythonExpression(["'", clock_mode, "' == 'realtime'"]))
    # Realtime: Fast DDS's UDP transport only, unless the user chose the transports (a
    # participant joining the domain stalls shared-memory senders ~333 ms; dds_transport).
    transports = [SetEnvironmentVariable(name, value, condition=realtime)
                  for name, value in realtime_transport_variables(os.environ)[0].items()]
    nodes = [
        Node(package=PACKAGE, executable="pph_driver", name="pph_driver", output="screen",
             parameters=driver_parameters, condition=separate),
        Node(package=PACKAGE, executable="notch_controller", name="notch_controller",
             output="screen", parameters=notch_parameters, condition=separate),
        Node(package=PACKAGE, executable="pointing_controller", name="pointing_controller",
             output="screen", parameters=controller_parameters, condition=separate),
        # No name=: a name remap would rename all three nodes of the process.
        Node(package=PACKAGE, executable="pph_graph", output="screen",
             parameters=driver_parameters, condition=IfCondition(composed)),
        Node(package=PACKAGE, executable="pph_recorder", name="pph_recorder", output="screen",
             parameters=[{"bag_path": ParameterValue(bag_path, value_type=str)}],
             condition=IfCondition(record)),
    ]
    return LaunchDescription([*arguments, *transports, *nodes])
