"""Install rules for the ament_python package hexapod_vibration."""

from glob import glob

from setuptools import find_packages, setup

PACKAGE = "hexapod_vibration"
SHARE = f"share/{PACKAGE}"

setup(
    name=PACKAGE,
    version="0.1.0",
    packages=find_packages(exclude=["test", "test.*"]),
    data_files=[
        ("share/ament_index/resource_index/packages", [f"resource/{PACKAGE}"]),
        (SHARE, ["package.xml"]),
        (f"{SHARE}/config", sorted(glob("config/*.yaml") + glob("config/*.xml"))),
        (f"{SHARE}/config/scenarios", sorted(glob("config/scenarios/*.yaml"))),
        (f"{SHARE}/config/presets", sorted(glob("config/presets/*.yaml"))),
        (f"{SHARE}/config/sweeps", sorted(glob("config/sweeps/*.yaml"))),
        (f"{SHARE}/launch", sorted(glob("launch/*.launch.py"))),
    ],
    install_requires=["setuptools"],
    zip_safe=True,
    maintainer="hexapod_vibration maintainers",
    maintainer_email="hexapod-vibration@example.com",
    description="Adaptive notch vibration suppression on a simulated pointing hexapod.",
    license="Apache-2.0",
    extras_require={"test": ["pytest"]},
    entry_points={
        "console_scripts": [
            # hexapod_vibration/executables.py: --help and argument errors before any heavy
            # import, quiet 130/143 exits; test/test_executables.py checks every script here.
            "pph_driver = hexapod_vibration.executables:pph_driver",
            "notch_controller = hexapod_vibration.executables:notch_controller",
            "pointing_controller = hexapod_vibration.executables:pointing_controller",
            "pph_graph = hexapod_vibration.executables:pph_graph",
            "pph_recorder = hexapod_vibration.executables:pph_recorder",
            "experiment = hexapod_vibration.executables:experiment",
            "analyze = hexapod_vibration.executables:analyze",
            "soak = hexapod_vibration.executables:soak",
            "hexapod_bench = hexapod_vibration.executables:hexapod_bench",
            "sweep = hexapod_vibration.executables:sweep",
            "hexapod_param = hexapod_vibration.executables:hexapod_param",
        ],
    },
)
