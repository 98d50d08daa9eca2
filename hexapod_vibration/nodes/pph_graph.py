"""``pph_graph``: the driver and both controllers composed in one process and one thread.

The same three nodes as ``pph_driver``, ``notch_controller`` and ``pointing_controller``
(same names, parameters, topics and QoS: ``ros2 param set /notch_controller mu ...`` and
``ros2 bag record`` work unchanged), built in one process, as a component container
would in C++. Their loop messages still go through rmw and DDS, but Fast DDS delivers
them within the process synchronously (intra-process delivery), so a sample costs no
inter-process hop and no thread wake-up: the driver publishes ``/pph/accel`` and
``/pph/eddy``, the controllers' callbacks run in the same spin and publish their commands,
and the driver applies them. On the project's 2-core machine this is what sustains
1 kHz in realtime with sub-millisecond latency and runs lockstep faster than real time
(numbers in docs/performance.md). Use the separate executables to put the
controllers on other machines or to restart one alone.

Usage: ``ros2 run hexapod_vibration pph_graph --ros-args --params-file
$(ros2 pkg prefix --share hexapod_vibration)/config/pph.yaml``: each node takes its own
section of the file. The ``executor`` of ``pph_driver`` serves all three.
"""

from __future__ import annotations

from hexapod_vibration.nodes.driver_loop import run_driver
from hexapod_vibration.nodes.notch_controller import NotchControllerNode
from hexapod_vibration.nodes.pointing_controller import PointingControllerNode
from hexapod_vibration.nodes.pph_driver import PPHDriver
from hexapod_vibration.ros.node_runner import run_node


def main(args: list[str] | None = None) -> None:
    """Entry point of ``ros2 run hexapod_vibration pph_graph``."""
    run_node("pph_graph", PPHDriver, run_driver, args=args,
             companions=(NotchControllerNode, PointingControllerNode),
             nodes=("pph_driver", "notch_controller", "pointing_controller"))


if __name__ == "__main__":
    main()
