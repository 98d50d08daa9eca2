"""The Fast DDS profile every node loads: a 100 ms heartbeat for the writers awaited at exit.

A node acknowledges nothing by itself: a RELIABLE reader sends its acknowledgement when the
writer's heartbeat asks for it, and Fast DDS sends one every 3 s by default (the periodic
heartbeat; a piggybacked one only after a send buffer's worth of data). At exit a node
waits until every reader acknowledged its last ``/diagnostics`` statuses, the driver also
its 1 kHz topics and ``/clock`` (``ros.matching.FLUSH_S``: a recorder must not lose a
run's tail), and so waited 0-3 s for the next heartbeat each time: measured (2026-12-07,
this 2-core machine, the graph tier of the tests) 128 node exits waited 70.8 s for their
``/diagnostics``, 51 driver exits 60.5 s for their loop topics; a lockstep experiment's
four nodes took 0.16-2.9 s each to stop after its last sample.

``config/fastdds_profiles.xml`` gives those writers (by topic name, as rmw_fastrtps looks
profiles up) a 100 ms heartbeat period and nothing else: the QoS policies stay the nodes'
own. A node loads it (:func:`use_package_profile`, before ``rclpy.init``) unless another
RMW is chosen or the user has a profiles file of their own (in either of
:data:`~hexapod_vibration.ros.dds_transport.PROFILES_VARIABLES`: it is left in charge).
"""

from __future__ import annotations

import os
from collections.abc import Mapping
from pathlib import Path

from hexapod_vibration.paths import config_path
from hexapod_vibration.ros.dds_transport import PROFILES_VARIABLES, uses_fastrtps

PROFILES_FILE = "fastdds_profiles.xml"
"""The package's profiles file, in ``config/``."""


def profile_variables(env: Mapping[str, str], profiles: Path) -> dict[str, str]:
    """The variables that make Fast DDS load ``profiles``: none for another RMW or a user's file."""
    if not uses_fastrtps(env) or any(env.get(name) for name in PROFILES_VARIABLES):
        return {}
    return {PROFILES_VARIABLES[0]: str(profiles)}


def use_package_profile() -> None:
    """Set :func:`profile_variables` in this process's environment (before ``rclpy.init``).

    Without the file (a broken install) nothing is set: the node then works as before and
    only its exit may wait up to 3 s (the colcon layout test checks the file is installed).
    """
    try:
        profiles = config_path(PROFILES_FILE)
    except FileNotFoundError:
        return
    os.environ.update(profile_variables(os.environ, profiles))
