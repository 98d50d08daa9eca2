"""launch/pph.launch.py: compiles, and names the executables, arguments and params file.

The launch package is not installed here (PyPI set-up), so the file is checked statically:
its syntax, the ``Node(...)`` actions it builds and the launch arguments it declares.
"""

from __future__ import annotations

import ast
import py_compile
from pathlib import Path

import yaml

ROOT = Path(__file__).resolve().parents[2]
LAUNCH_FILE = ROOT / "launch" / "pph.launch.py"
PARAMS_FILE = ROOT / "config" / "pph.yaml"
NODES = ("pph_driver", "notch_controller", "pointing_controller")


def _calls(tree: ast.AST, name: str) -> list[ast.Call]:
    return [n for n in ast.walk(tree) if isinstance(n, ast.Call)
            and getattr(n.func, "id", getattr(n.func, "attr", None)) == name]


def _keywords(call: ast.Call, constants: dict[str, object]) -> dict[str, object]:
    values = {}
    for kw in call.keywords:
        if isinstance(kw.value, ast.Constant):
            values[kw.arg] = kw.value.value
        elif isinstance(kw.value, ast.Name) and kw.value.id in constants:
            values[kw.arg] = constants[kw.value.id]
        else:
            values[kw.arg] = kw.value
    return values


def test_launch_file_compiles_and_starts_the_three_nodes(tmp_path):
    py_compile.compile(str(LAUNCH_FILE), cfile=str(tmp_path / "pph.launch.pyc"), doraise=True)
    source = LAUNCH_FILE.read_text()
    tree = ast.parse(source)
    constants = {t.id: n.value.value for n in tree.body if isinstance(n, ast.Assign)
                 for t in n.targets if isinstance(t, ast.Name)
                 and isinstance(n.value, ast.Constant)}
    assert any(isinstance(n, ast.FunctionDef) and n.name == "generate_launch_description"
               for n in tree.body)

    nodes = [_keywords(c, constants) for c in _calls(tree, "Node")]
    executables = {n["executable"]: n for n in nodes}
    assert set(executables) == {*NODES, "pph_graph", "pph_recorder"}
    for name, node in executables.items():
        assert node["package"] == "hexapod_vibration"
        if name != "pph_graph":
            assert node["name"] == name
    # pph_graph holds three nodes: a name remap would rename them all.
    assert "name" not in executables["pph_graph"]
    assert "condition" in executables["pph_recorder"]          # only with record:=true
    for name in (*NODES, "pph_graph"):                        # separate xor composed
        assert "parameters" in executables[name]
        assert "condition" in executables[name]
    assert source.count("UnlessCondition(composed)") == 1
    assert "IfCondition(composed)" in source

    arguments = {_keywords(c, constants).get("name") or c.args[0].value
                 for c in _calls(tree, "DeclareLaunchArgument")}
    assert arguments == {"params_file", "clock_mode", "record", "bag_path", "composed",
                         "realtime_priority", "command_delay_samples",
                         "identification_analysis"}
    # The choices of the notch's analysis place are the parameter's.
    from hexapod_vibration.parameter_specs import ANALYSIS_PLACES
    assert "choices=" + str(list(ANALYSIS_PLACES)).replace("'", '"') in source
    # The realtime default is the experiment's (one definition, checked here).
    from hexapod_vibration.tools.experiment_setup import REALTIME_COMMAND_DELAY_SAMPLES
    assert constants["REALTIME_COMMAND_DELAY_SAMPLES"] == REALTIME_COMMAND_DELAY_SAMPLES
    assert 'choices=["lockstep", "realtime"]' in source
    # The params file comes from the package's share directory.
    assert "get_package_share_directory" in source
    assert constants["PARAMS_FILE"] == PARAMS_FILE.name and '"config"' in source


def test_params_file_has_a_section_per_node():
    params = yaml.safe_load(PARAMS_FILE.read_text())
    assert set(params) == set(NODES)
    for name in NODES:
        assert set(params[name]) == {"ros__parameters"}
    # setup.py installs both files into the share directory.
    setup = (ROOT / "setup.py").read_text()
    assert 'glob("launch/*.launch.py")' in setup and 'glob("config/*.yaml")' in setup
