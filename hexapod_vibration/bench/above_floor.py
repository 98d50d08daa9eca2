"""What the nodes add to the message path: the graph's budget against the floor's, one run.

The CPU budget (:mod:`~hexapod_vibration.bench.node_budget`) measures the Table 1 graph; the
floor (:mod:`~hexapod_vibration.bench.message_floor`) the same processes, topics and codec
computing nothing. Their difference, per process and in the lockstep rate, is the nodes' own
work, the part code can still cut; the floor is what two cores charge for the exchange. Both
come from the same ``make bench`` run, a few minutes apart (the host's speed can move in
between: the figures say which run they compare).
"""

from __future__ import annotations

from typing import Any

from hexapod_vibration.bench.floor_nodes import ROLES
from hexapod_vibration.bench.node_budget import NODES

RATE_PAIRS = (("processes/lockstep/recorder", "lockstep/recorder", "through processes"),
              ("composed/lockstep/recorder", "lockstep/recorder/composed", "composed"))
"""(the budget's set-up, the floor's, what to call it) of the lockstep rates compared: both
with the recorder (the ROS loop table's runs have none, and the floor through processes
always has one)."""
BUDGET_KEY, FLOOR_KEY = RATE_PAIRS[0][:2]
"""The set-ups whose CPU per process is compared: lockstep through processes, recorder."""
NODE_OF_ROLE = dict(zip(ROLES, NODES, strict=True))


def cpu_above_floor(budget: dict[str, Any], floor: dict[str, Any]) -> dict[str, dict[str, float]]:
    """Per process: its CPU (us per sample) in the graph, in the floor, and the difference.

    Lockstep through processes with the recorder in both; {} if either is missing or failed.
    """
    graph = budget.get(BUDGET_KEY, {}).get("cpu_us_per_sample", {})
    alone = floor.get(FLOOR_KEY, {}).get("cpu_us_per_sample", {})
    rows = {}
    for role, node in NODE_OF_ROLE.items():
        if node in graph and role in alone:
            used = graph[node]["process"]
            rows[role] = {"graph": used, "floor": alone[role], "above": used - alone[role]}
    return rows


def window_rate(result: dict[str, Any]) -> float | None:
    """A budget window's lockstep rate (x real time): its samples over its wall seconds.

    The driver's sample count comes from its /diagnostics (every 1000 samples), so the rate
    of a 30 s window is good to about 0.03x.
    """
    samples, wall_s = result.get("samples"), result.get("wall_s")
    return samples / wall_s / 1000.0 if samples and wall_s else None


def above_floor_markdown(budget: dict[str, Any], floor: dict[str, Any]) -> str:
    """The table of :func:`cpu_above_floor` and the lockstep rates against the floor's."""
    rows = cpu_above_floor(budget, floor)
    lines = []
    if rows:
        lines += ["| process | graph | message path alone | the nodes' own |",
                  "|---|---:|---:|---:|"]
        lines += [f"| {role} | {r['graph']:.0f} | {r['floor']:.0f} | {r['above']:.0f} |"
                  for role, r in rows.items()]
        total = {k: sum(r[k] for r in rows.values()) for k in ("graph", "floor", "above")}
        lines += [f"| total | {total['graph']:.0f} | {total['floor']:.0f} | "
                  f"{total['above']:.0f} |", ""]
    for budget_key, floor_key, name in RATE_PAIRS:
        rate = window_rate(budget.get(budget_key, {}))
        alone = floor.get(floor_key, {}).get("x_real_time")
        if rate and alone:
            lines.append(f"- Lockstep {name}, with the recorder: the graph {rate:.2f}x (the "
                         f"budget's {budget_key} window, control on), the message path alone "
                         f"{alone:.2f}x: {rate / alone:.2f} of its rate.")
    return "\n".join(lines)
