"""Robot descriptions: both robots load, their URDF agrees with their YAML, bad files fail clearly."""

import xml.etree.ElementTree as ET

import numpy as np
import pytest
import yaml

from wmm_control.errors import ConfigError
from wmm_control.robot_config import load_robot


@pytest.mark.parametrize('name,alias', [('steerable', 'A'), ('mecanum', 'b')])
def test_both_robots_load_by_name_and_alias(name, alias):
    cfg = load_robot(name)
    assert load_robot(alias).name == cfg.name == name
    assert cfg.urdf_path.is_file()
    assert len(cfg.arm.joints) == 7


def test_limits_come_from_the_urdf_and_the_yaml_overrides_them(tmp_path):
    cfg = load_robot('steerable')
    joints = {j.get('name'): j for j in ET.parse(cfg.urdf_path).getroot().iter('joint')}
    assert cfg.arm.velocity[3] == float(joints['arm_joint_4'].find('limit').get('velocity'))
    raw = yaml.safe_load(cfg.yaml_path.read_text())
    raw['robot']['urdf'] = str(cfg.urdf_path)
    raw['robot']['arm']['velocity'] = [0.5] * 7
    raw['robot']['arm'].pop('acceleration')
    raw['robot']['steerable']['wheel_radius'] = 0.1
    path = tmp_path / 'override.yaml'
    path.write_text(yaml.safe_dump(raw))
    over = load_robot(path)
    np.testing.assert_allclose(over.arm.velocity, 0.5)
    np.testing.assert_allclose(over.arm.acceleration, 1.0)  # the default rule: 2 × the velocity limit
    assert over.steerable.wheel_radius == 0.1
    np.testing.assert_allclose(over.arm.position_upper, cfg.arm.position_upper)


def test_steerable_geometry_is_sorour_table_i():
    cfg = load_robot('steerable')
    s = cfg.steerable
    # front-left, front-right, rear-left, rear-right, with their signs: swapped wheels fail
    np.testing.assert_allclose(s.hips, [[0.24, 0.19], [0.24, -0.19], [-0.24, 0.19], [-0.24, -0.19]])
    assert s.wheel_radius == 0.09 and s.wheel_offset == 0.045
    # each steer joint of the URDF sits on its hip (the same order as the YAML's hips)
    joints = {j.get('name'): j for j in ET.parse(cfg.urdf_path).getroot().iter('joint')}
    origins = [[float(v) for v in joints[name].find('origin').get('xyz').split()[:2]] for name in s.steer_joints]
    np.testing.assert_allclose(origins, s.hips)


def test_mecanum_limits_are_xing_table_1():
    cfg = load_robot('mecanum')
    np.testing.assert_allclose(cfg.base.velocity, [0.25, 0.25, 1.0])
    np.testing.assert_allclose(cfg.base.acceleration, [0.025, 0.025, 1.5])
    np.testing.assert_allclose(cfg.arm.velocity, [1.75] * 4 + [3.14] * 3)
    np.testing.assert_allclose(cfg.arm.acceleration, [3.0] * 4 + [5.0] * 3)
    np.testing.assert_allclose(cfg.arm.position_upper[[1, 3, 5]], [2.2, 2.5, 2.0])
    assert np.all(np.isinf(cfg.arm.position_upper[[0, 2, 4, 6]]))


def test_unknown_robot_name_lists_the_valid_ones():
    with pytest.raises(ConfigError, match=r"unknown robot 'C'.*mecanum.*panda_diff.*steerable.*ur_mecanum"):
        load_robot('C')
