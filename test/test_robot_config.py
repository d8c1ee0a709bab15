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


@pytest.mark.parametrize('name', ['steerable', 'mecanum'])
def test_urdf_limits_equal_yaml_limits(name):
    cfg = load_robot(name)
    joints = {j.get('name'): j for j in ET.parse(cfg.urdf_path).getroot().iter('joint')}
    for jname, vmax in cfg.joint_velocity_limits.items():
        limit = joints[jname].find('limit')
        assert float(limit.get('velocity')) == pytest.approx(vmax), jname
    for i, jname in enumerate(cfg.arm.joints):
        joint = joints[jname]
        if np.isfinite(cfg.arm.position_upper[i]):
            assert joint.get('type') == 'revolute'
            assert float(joint.find('limit').get('upper')) == pytest.approx(cfg.arm.position_upper[i])
            assert float(joint.find('limit').get('lower')) == pytest.approx(cfg.arm.position_lower[i])
        else:
            assert joint.get('type') == 'continuous'


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


def _write_variant(tmp_path, mutate):
    src = load_robot('steerable')
    raw = yaml.safe_load(src.yaml_path.read_text())
    raw['robot']['urdf'] = str(src.urdf_path)
    mutate(raw['robot'])
    path = tmp_path / 'variant.yaml'
    path.write_text(yaml.safe_dump(raw))
    return path


@pytest.mark.parametrize('mutate,message', [
    (lambda r: r['arm'].pop('velocity'), "missing key 'velocity'"),
    (lambda r: r['arm'].__setitem__('velocity', [1.0] * 6), 'arm.velocity: expected 7 numbers'),
    (lambda r: r['arm'].__setitem__('acceleration', [1.0] * 6 + [-1.0]), 'must be finite and > 0'),
    (lambda r: r.__setitem__('base_type', 'legged'), 'base_type'),
    (lambda r: r['steerable'].__setitem__('hips', [[0.2, 0.1]] * 3), 'hips'),
    (lambda r: r.__setitem__('urdf', 'nowhere.urdf'), 'file not found'),
    (lambda r: r['arm'].__setitem__('dexterous', [9.0] * 7), 'dexterous: outside the position limits'),
    (lambda r: r.pop('method'), "key 'method' must be a name"),
])
def test_invalid_descriptions_raise_config_error_naming_the_key(tmp_path, mutate, message):
    with pytest.raises(ConfigError, match=message):
        load_robot(_write_variant(tmp_path, mutate))


def test_unknown_robot_name_lists_the_valid_ones():
    with pytest.raises(ConfigError, match=r"unknown robot 'C'.*mecanum.*steerable"):
        load_robot('C')
