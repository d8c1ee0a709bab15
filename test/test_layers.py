"""The package's layers, arrows only downward: no module imports one of a higher layer, at
module level or inside a function.

core (ROS-free numerics and the robot description) → simulator (``sim_bridge``) → ROS nodes →
experiments → command-line tools. Every module belongs to a layer listed in :data:`LAYERS`; a
new package or top-level module must be placed there.
"""

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ('wmm_control', 'sim_bridge')
ORDER = ('core', 'simulator', 'nodes', 'experiments', 'cli')
#: Entries that place the module itself only, not those below it.
ITSELF_ONLY = {'wmm_control'}

#: The layer of each package, subpackage or module; a module takes the entry of its longest
#: dotted prefix. ``wmm_control`` itself stands for its ``__init__`` only.
LAYERS = {
    'wmm_control': 'core',
    'wmm_control.errors': 'core',
    'wmm_control.checks': 'core',
    'wmm_control.paths': 'core',
    'wmm_control.resources': 'core',  # the one resolver of a URDF's package://, file:// and relative paths
    'wmm_control.geometry': 'core',  # SE(2), SO(3), quaternions, angles, continuous joints, limits scaling
    'wmm_control.urdf': 'core',
    'wmm_control.robot_config': 'core',
    'wmm_control.kinematics': 'core',
    'wmm_control.base': 'core',
    'wmm_control.resolvers': 'core',
    'wmm_control.cycle': 'core',  # one control period: resolver, base, compensation
    'wmm_control.planning': 'core',  # where to stand, a base path (OMPL), timed
    'wmm_control.viewer': 'core',  # the browser viewer's scene, panel and drag, ROS-free
    # the scenario file format (goals, trajectories), ROS-free: the goal_sequencer node plays it
    'wmm_control.experiments.scenario': 'core',
    'wmm_control.experiments.trajectories': 'core',
    'sim_bridge': 'simulator',
    'sim_bridge.node': 'nodes',  # wmm_sim, the simulator's ROS node
    'sim_bridge.node_params': 'nodes',  # its parameters
    'sim_bridge.outputs': 'nodes',  # its messages
    'wmm_control.nodes': 'nodes',
    'wmm_control.launching': 'nodes',  # the nodes the launch files start
    'wmm_control.experiments': 'experiments',
    'wmm_control.cli': 'cli',
}


def _modules():
    """``{dotted name: path}`` of every module of the packages."""
    out = {}
    for package in PACKAGES:
        for path in sorted((ROOT / package).rglob('*.py')):
            parts = path.relative_to(ROOT).with_suffix('').parts
            out['.'.join(parts[:-1] if parts[-1] == '__init__' else parts)] = path
    return out


MODULES = _modules()


def layer_of(module):
    """The layer of ``module`` (a dotted name), None when :data:`LAYERS` does not place it."""
    parts = module.split('.')
    for n in range(len(parts), 0, -1):
        name = '.'.join(parts[:n])
        if name in LAYERS and (name not in ITSELF_ONLY or n == len(parts)):
            return LAYERS[name]
    return None


def imports(module, source):
    """``[(line, imported module)]``: every import of one of the packages in ``source``, at any
    depth (module level, functions, classes), relative ones resolved."""
    package = (
        module.split('.') if module in MODULES and MODULES[module].name == '__init__.py' else module.split('.')[:-1]
    )
    out = []
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.Import):
            out += [(node.lineno, alias.name) for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ''
            if node.level:
                base = '.'.join(package[: len(package) - node.level + 1] + ([base] if base else []))
            for alias in node.names:
                full = f'{base}.{alias.name}'
                out.append((node.lineno, full if full in MODULES else base))
    return [(line, name) for line, name in out if name.split('.')[0] in PACKAGES]


def upward(module, source):
    """``[(line, imported module)]`` of the imports in ``source`` (of ``module``) from a higher layer."""
    rank = ORDER.index(layer_of(module))
    return [(line, name) for line, name in imports(module, source) if ORDER.index(layer_of(name)) > rank]


def test_every_module_has_a_layer():
    unplaced = [m for m in MODULES if layer_of(m) is None]
    assert not unplaced, f'place these in LAYERS: {unplaced}'
    assert set(LAYERS.values()) <= set(ORDER)
    stale = [name for name in LAYERS if not any(m == name or m.startswith(name + '.') for m in MODULES)]
    assert not stale, f'LAYERS names modules that do not exist: {stale}'


@pytest.mark.parametrize('module', sorted(MODULES))
def test_no_module_imports_a_higher_layer(module):
    found = upward(module, MODULES[module].read_text())
    assert not found, f'{module} ({layer_of(module)}) imports from higher layers: ' + ', '.join(
        f'line {line}: {name} ({layer_of(name)})' for line, name in found
    )


def test_an_upward_import_inside_a_function_is_found():
    source = (
        'from wmm_control.errors import ConfigError\n\n\n'
        'def f():\n    from wmm_control.nodes.parameters import load_defaults\n    return load_defaults\n\n\n'
        'class C:\n    def g(self):\n        from ..cli import experiment\n        return experiment\n'
    )
    assert upward('wmm_control.kinematics.model', source) == [
        (5, 'wmm_control.nodes.parameters'),
        (11, 'wmm_control.cli.experiment'),
    ]
    assert upward('wmm_control.cli.experiment', source) == []
