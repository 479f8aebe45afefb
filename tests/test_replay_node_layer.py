"""The node layer, read without rclpy: what it imports and that it holds no pipeline logic."""

from __future__ import annotations

import ast
import sys
from pathlib import Path

PACKAGE = Path(__file__).resolve().parent.parent / 'stockpile_ros'
NODES = sorted((PACKAGE / 'nodes').glob('*.py'))

ROS = {'rclpy', 'rcl_interfaces', 'rosidl_runtime_py', 'std_msgs', 'std_srvs', 'sensor_msgs',
       'nav_msgs', 'tf2_msgs', 'diagnostic_msgs', 'visualization_msgs',
       'stockpile_msgs'}  # fmt: skip
# The core components a node may call; everything else (stages, numpy work) stays behind them.
# playback: the bag player's loops (ROS-free); errors: the exception classes a main() reports.
CORE = {'ros', 'ros.publications', 'components', 'settings', 'errors', 'playback', 'bagio.reader'}
HEAVY = {'numpy', 'scipy', 'open3d', 'pycolmap', 'cv2', 'rosbags', 'matplotlib'}


def _imports(tree: ast.Module) -> list[tuple[int, str]]:
    """(relative level, module) of every import statement anywhere in the module."""
    out = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            out += [(0, alias.name) for alias in node.names]
        elif isinstance(node, ast.ImportFrom) and node.module is None:
            out += [(node.level, alias.name) for alias in node.names]  # from .. import topics
        elif isinstance(node, ast.ImportFrom):
            out.append((node.level, node.module))
    return out


def test_node_modules_import_only_ros_stdlib_and_core_components() -> None:
    assert {p.stem for p in NODES} >= {'keyframe_node', 'reconstruction_node',
                                       'segmentation_node', 'rig', 'common'}  # fmt: skip
    siblings = {p.stem for p in NODES}
    for path in NODES:
        for level, name in _imports(ast.parse(path.read_text())):
            root = name.split('.')[0]
            where = f'{path.name}: {"." * level}{name}'
            if level == 0:
                assert root not in HEAVY, where
                assert root in ROS or root in sys.stdlib_module_names, where
            elif level == 1:
                assert name in siblings, where
            else:
                assert level == 2 and name in CORE, where


def test_node_modules_hold_no_numeric_work() -> None:
    for path in NODES:
        tree = ast.parse(path.read_text())
        names = {n.id for n in ast.walk(tree) if isinstance(n, ast.Name)}
        assert not names & {'np', 'numpy', 'cv2', 'o3d'}, path.name
        # Module level: imports, constants, node classes and main(); no helper algorithms.
        for node in tree.body:
            if isinstance(node, ast.FunctionDef):
                # qos_profile: the player's QoS per table class (to move into common.py).
                allowed = {'main', 'spin', 'declare_settings', 'current_settings', 'now_ns',
                           '_descriptor', '_build', '_array', 'qos_profile', 'subscribe',
                           'get_message', 'get_service', '_interface'}  # fmt: skip
                assert node.name in allowed, f'{path.name}: {node.name}'
        # The inbox's thread loops over its queue: that is wiring too.
        inbox = [f for f in ast.walk(tree) if isinstance(f, ast.FunctionDef) and f.name == '_work']
        queue_loops = {id(n) for f in inbox for n in ast.walk(f) if isinstance(n, ast.While)}
        for node in ast.walk(tree):
            if isinstance(node, (ast.For, ast.While)) and id(node) not in queue_loops:
                # Loops only walk declared parameters, publications or nodes.
                target = ast.unparse(node.iter) if isinstance(node, ast.For) else 'while'
                assert target in {'settings_for(component)', 'publications', 'nodes',
                                  'types.items()'}, f'{path.name}: loop over {target}'  # fmt: skip


def test_the_measuring_path_never_imports_the_tools() -> None:
    # The simulator, the evaluation and the test scenes are tools; only their commands use them.
    commands = {PACKAGE / 'cli' / 'simulate.py', PACKAGE / 'cli' / 'evaluate.py'}
    for path in PACKAGE.rglob('*.py'):
        if 'tools' in path.relative_to(PACKAGE).parts or path in commands:
            continue
        for level, name in _imports(ast.parse(path.read_text())):
            assert 'tools' not in name.split('.'), f'{path}: imports {"." * level}{name}'


def test_nothing_outside_the_node_layer_imports_ros() -> None:
    for path in PACKAGE.rglob('*.py'):
        if path.parent.name == 'nodes':
            continue
        for level, name in _imports(ast.parse(path.read_text())):
            if level == 0:
                assert name.split('.')[0] not in ROS, f'{path}: imports {name}'


def test_console_scripts_point_at_the_node_mains() -> None:
    setup = (PACKAGE.parent / 'setup.py').read_text()
    launch = (PACKAGE.parent / 'launch' / 'stockpile.launch.py').read_text()
    for script in ('keyframe_node', 'reconstruction_node', 'segmentation_node', 'rig'):
        assert f"'{script} = stockpile_ros.nodes.{script}:main'" in setup
        assert f"'{script}'" in launch
        tree = ast.parse((PACKAGE / 'nodes' / f'{script}.py').read_text())
        assert any(isinstance(n, ast.FunctionDef) and n.name == 'main' for n in tree.body)
