"""ROS params files: the parameters one file gives one node (no ROS import)."""

from __future__ import annotations

from pathlib import Path
from typing import Any


def node_parameters(path: Path, node: str) -> dict[str, Any] | str:
    """The parameters ``path`` gives ``node`` (``/node``, ``node`` or ``**`` key), or why not.

    Returns the ``ros__parameters`` mapping, or a one-line reason (unreadable file, no
    section for the node).
    """
    import yaml

    try:
        content = yaml.safe_load(Path(path).read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, yaml.YAMLError) as exc:
        return f"cannot read {path}: {' '.join(str(exc).split())}"
    keys = (node, node.lstrip("/"), "/**", "**")
    section = next((content[k] for k in keys if isinstance(content, dict) and k in content),
                   None)
    values = section.get("ros__parameters") if isinstance(section, dict) else None
    if not isinstance(values, dict):
        return f"{path} has no parameters for {node} (expected {node}: ros__parameters: ...)"
    return values
