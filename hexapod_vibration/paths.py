"""Locate the package's data files (``config/``, ``config/scenarios/``, ``launch/``).

After ``colcon build`` the files are installed in the package's share directory, found
through the ament index. In a source checkout installed with ``pip install -e .`` (the
virtualenv set-up) there is no ament index entry, and the files are read from the source
tree: the folder that holds both ``hexapod_vibration/`` and ``config/``.
"""

from __future__ import annotations

from pathlib import Path

PACKAGE_NAME = "hexapod_vibration"


def _ament_share_directory() -> Path | None:
    """The share directory from the ament index, or ``None`` if the package is not indexed."""
    try:
        from ament_index_python.packages import (
            PackageNotFoundError,
            get_package_share_directory,
        )
    except ImportError:  # analysis without ROS installed
        return None
    try:
        return Path(get_package_share_directory(PACKAGE_NAME))
    except (PackageNotFoundError, OSError):  # OSError: AMENT_PREFIX_PATH unset or empty
        return None


def _source_root() -> Path:
    """The source tree's root: the parent folder of this Python package."""
    return Path(__file__).resolve().parent.parent


def share_directory() -> Path:
    """Folder holding ``config/`` (and ``launch/``): ament share directory or source root.

    Raises:
        FileNotFoundError: Neither location has a ``config/`` folder.
    """
    for candidate in (_ament_share_directory(), _source_root()):
        if candidate is not None and (candidate / "config").is_dir():
            return candidate
    raise FileNotFoundError(
        f"cannot find the config/ folder of {PACKAGE_NAME}: not in the ament index "
        f"(AMENT_PREFIX_PATH) and not in the source tree at {_source_root()}"
    )


def config_path(name: str) -> Path:
    """Path of ``config/<name>`` (``name`` includes the extension, e.g. ``"plant.yaml"``).

    Raises:
        FileNotFoundError: The file does not exist; the message lists the folder's files.
    """
    path = share_directory() / "config" / name
    if not path.is_file():
        available = sorted(p.name for p in path.parent.glob("*.yaml"))
        raise FileNotFoundError(
            f'no config file {name!r} in {path.parent}; available: {", ".join(available) or "none"}'
        )
    return path


def available_scenarios() -> list[str]:
    """Names of the scenarios in ``config/scenarios/`` (file names without ``.yaml``)."""
    folder = share_directory() / "config" / "scenarios"
    return sorted(p.stem for p in folder.glob("*.yaml"))


def scenario_path(name: str) -> Path:
    """Path of ``config/scenarios/<name>.yaml``.

    Raises:
        FileNotFoundError: Unknown scenario; the message lists the available ones.
    """
    path = share_directory() / "config" / "scenarios" / f"{name}.yaml"
    if not path.is_file():
        raise FileNotFoundError(
            f'unknown scenario {name!r} (no {path}); available scenarios: '
            f'{", ".join(available_scenarios()) or "none"}'
        )
    return path
