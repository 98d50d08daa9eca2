"""The rclpy version gate of the private fast path, and the public API fallback."""

import os
import subprocess
import sys

import numpy as np

from hexapod_vibration.cdr import clock_cdr, encode_strut_cdr
from hexapod_vibration.ros.rclpy_internals import (
    PUBLIC_API_ENV,
    VERIFIED_RCLPY_VERSION,
    fast_path,
    fast_path_problem,
    rclpy_version,
)

RUN = 1234567890123


# ------------------------------------------------------------------ the version gate
def test_verified_rclpy_is_installed_and_the_fast_path_is_on():
    assert rclpy_version() == VERIFIED_RCLPY_VERSION
    assert fast_path_problem() == "" and fast_path()


def test_public_api_fallback_gives_the_same_bytes(tmp_path):
    """With the public API forced: the same loop bytes, the reason logged once.

    The executor takes the loop messages then (no serialized take here); the codec does not
    depend on the gate, its bytes are what rclpy deserializes into the same message.
    """
    script = (
        "import numpy as np\n"
        "from hexapod_vibration import cdr\n"
        "from hexapod_vibration.ros import rclpy_internals as ri\n"
        "assert not ri.fast_path() and not ri.fast_path()\n"
        "assert ri.take_serialized_batch(None, 5) == []\n"
        "from rclpy.serialization import deserialize_message\n"
        "from std_msgs.msg import Float64MultiArray\n"
        f"raw = cdr.encode_strut_cdr(np.arange(6.0), 5, {RUN})\n"
        f"expected = {encode_strut_cdr(np.arange(6.0), 5, RUN)!r}\n"
        "assert raw == expected\n"
        "assert (deserialize_message(raw, Float64MultiArray)\n"
        "        == deserialize_message(expected, Float64MultiArray))\n"
        "assert cdr.decode_strut_cdr(raw).run == cdr.decode_strut_cdr(expected).run\n"
        f"assert cdr.clock_cdr(1500) == {clock_cdr(1500)!r}\n"
        "print(ri.fast_path_problem())\n")
    env = dict(os.environ, **{PUBLIC_API_ENV: "1"})
    result = subprocess.run([sys.executable, "-c", script], env=env, capture_output=True,
                            text=True, timeout=120)
    assert result.returncode == 0, result.stderr
    assert PUBLIC_API_ENV in result.stdout
    assert result.stderr.count("using rclpy's public API") == 1, result.stderr
