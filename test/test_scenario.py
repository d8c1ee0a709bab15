"""wmm_control.experiments.scenario: a scenario file names its robot; the core assumes none."""

import pytest

from wmm_control.errors import ConfigError
from wmm_control.experiments.scenario import load_scenario
from wmm_control.paths import config_path

NO_ROBOT = """scenario:
  name: no_robot
  frame: world
  duration: 1.0
  goals:
    - {t: 0.0, pose: [1.0, 0.0, 1.0, 0.0, 0.0, 0.0]}
"""


@pytest.mark.parametrize('robot', ['', None])
def test_a_scenario_without_its_robot_is_refused_naming_the_file(tmp_path, robot):
    path = tmp_path / 'no_robot.yaml'
    path.write_text(NO_ROBOT if robot is None else NO_ROBOT.replace('  frame:', f'  robot: "{robot}"\n  frame:'))
    with pytest.raises(ConfigError, match=r'no_robot\.yaml.*robot is required'):
        load_scenario(str(path))
    path.write_text(NO_ROBOT.replace('  frame:', '  robot: mecanum\n  frame:'))
    assert load_scenario(str(path)).robot == 'mecanum'


def test_every_shipped_scenario_names_its_robot():
    shipped = sorted(config_path('scenarios').glob('*.yaml'))
    assert shipped
    for path in shipped:
        assert load_scenario(str(path)).robot, path.name
