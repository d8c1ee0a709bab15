"""ament_python build of wmm_control (colcon build, or pip install)."""

from pathlib import Path

from setuptools import find_packages, setup

PACKAGE = 'wmm_control'
HERE = Path(__file__).resolve().parent


def config_data_files():
    """Everything under config/ goes to share/wmm_control/config/, folder by folder."""
    entries = {}
    for path in sorted((HERE / 'config').rglob('*')):
        if path.is_file():
            rel = path.relative_to(HERE)
            entries.setdefault(str(Path('share') / PACKAGE / rel.parent), []).append(str(rel))
    return sorted(entries.items())


setup(
    name=PACKAGE,
    version='0.1.0',
    packages=find_packages(include=['wmm_control', 'wmm_control.*', 'sim_bridge', 'sim_bridge.*']),
    data_files=[
        ('share/ament_index/resource_index/packages', ['resource/' + PACKAGE]),
        ('share/' + PACKAGE, ['package.xml']),
        *config_data_files(),
        (
            'share/' + PACKAGE + '/launch',
            sorted(str(p.relative_to(HERE)) for p in (HERE / 'launch').glob('*.launch.py')),
        ),
    ],
    install_requires=['setuptools', 'numpy', 'pyyaml'],
    zip_safe=True,
    maintainer='wmm_control maintainers',
    maintainer_email='maintainers@wmm-control.dev',
    description='Whole-body motion control of wheeled mobile manipulators.',
    license='Apache-2.0',
    # cluster: --cluster of wmm_randomized and wmm_experiment (Ray tasks), scripts/requirements-cluster.txt
    extras_require={'test': ['pytest', 'hypothesis', 'ray[client]', 'example-robot-data'], 'cluster': ['ray[client]']},
    entry_points={
        'console_scripts': [
            'wmm_model = wmm_control.cli.model_info:main',
            'wmm_sim = sim_bridge.node:main',
            'swmr_controller = wmm_control.nodes.swmr_controller:main',
            'mecanum_controller = wmm_control.nodes.mecanum_controller:main',
            'differential_controller = wmm_control.nodes.mecanum_controller:main_differential',
            'wmm_robot = wmm_control.cli.robot_setup:main',
            'redundancy_resolver = wmm_control.nodes.redundancy_resolver:main',
            'goal_sequencer = wmm_control.nodes.goal_sequencer:main',
            'goal_planner = wmm_control.nodes.goal_planner:main',
            'wmm_viewer = wmm_control.nodes.viewer:main',
            'wmm_experiment = wmm_control.cli.experiment:main',
            'wmm_randomized = wmm_control.cli.randomized:main',
        ],
    },
)
