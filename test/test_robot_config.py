"""Robot descriptions: both robots load, their URDF agrees with their YAML, bad files fail clearly."""

import xml.etree.ElementTree as ET

import numpy as np
import pytest
import yaml

from urdf_factory import SIX_MECANUM_WHEELS, SIX_ROLLER_ANGLES, write_mecanum_robot
from wmm_control.base import MecanumKinematics
from wmm_control.errors import ConfigError
from wmm_control.robot_config import MecanumBase, load_robot


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
    assert over.base.wheel_radius == 0.1
    np.testing.assert_allclose(over.arm.position_upper, cfg.arm.position_upper)


def test_steerable_geometry_is_sorour_table_i():
    cfg = load_robot('steerable')
    s = cfg.base
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


def test_a_six_wheel_mecanum_base_comes_from_its_urdf_and_roller_angles(tmp_path):
    cfg = load_robot(write_mecanum_robot(tmp_path, SIX_MECANUM_WHEELS, SIX_ROLLER_ANGLES))
    base = cfg.base
    assert isinstance(base, MecanumBase) and base.family == 'mecanum' and base.axes == (0, 1, 2)
    assert base.wheel_joints == tuple(f'wheel_{tag}_joint' for tag, _, _ in SIX_MECANUM_WHEELS)
    assert base.command_groups == {'wheel': base.wheel_joints} and base.joints == base.wheel_joints
    np.testing.assert_allclose(base.positions, [(x, y) for _, x, y in SIX_MECANUM_WHEELS], atol=1e-12)
    np.testing.assert_allclose(base.roller_angles, SIX_ROLLER_ANGLES)
    assert base.wheel_radius == 0.08 and base.wheel_rate_limit == 12.0  # the URDF's cylinders and limits
    assert {n: cfg.joint_velocity_limits[n] for n in base.wheel_joints} == dict.fromkeys(base.wheel_joints, 12.0)
    kin = MecanumKinematics.from_config(base)
    for twist in ([0.2, 0.0, 0.0], [0.0, -0.1, 0.0], [0.05, 0.1, -0.3]):
        np.testing.assert_allclose(kin.twist_from_wheels(kin.wheel_rates(twist)), twist, rtol=0, atol=1e-12)


def test_mecanum_roller_angles_default_to_the_usual_pattern_and_bad_ones_fail_clearly(tmp_path):
    off_axis = [(tag, x if x else 0.1, y) for tag, x, y in SIX_MECANUM_WHEELS]  # the middle pair ahead of the centre
    base = load_robot(write_mecanum_robot(tmp_path, off_axis)).base
    np.testing.assert_allclose(base.roller_angles, np.pi / 4 * np.array([1, -1, 1, -1, -1, 1]))
    with pytest.raises(
        ConfigError, match=r"wheels \['wheel_ml_joint', 'wheel_mr_joint'\] sit on an axis.*roller_angles"
    ):
        load_robot(write_mecanum_robot(tmp_path, SIX_MECANUM_WHEELS))
    with pytest.raises(ConfigError, match=r'mecanum_n.yaml: mecanum.roller_angles.*rank 2'):
        load_robot(write_mecanum_robot(tmp_path, SIX_MECANUM_WHEELS, [np.pi / 4] * 6))
    with pytest.raises(ConfigError, match=r'mecanum.wheel_joints: expected a list of at least 3'):
        load_robot(write_mecanum_robot(tmp_path, SIX_MECANUM_WHEELS[:2]))


def test_mecanum_d1_d2_set_every_wheels_distances_with_the_urdfs_signs(tmp_path):
    cfg = load_robot('ur_mecanum')
    raw = yaml.safe_load(cfg.yaml_path.read_text())
    raw['robot']['urdf'] = str(cfg.urdf_path)
    raw['robot']['mecanum'].update(d1=0.3, d2=0.2)
    path = tmp_path / 'd1d2.yaml'
    path.write_text(yaml.safe_dump(raw))
    base = load_robot(path).base
    np.testing.assert_allclose(base.positions, np.sign(cfg.base.positions) * [0.3, 0.2])
    np.testing.assert_allclose(base.roller_angles, cfg.base.roller_angles)


@pytest.mark.parametrize(
    'robot, family, axes, groups',
    [
        ('steerable', 'steerable', (0, 1, 2), ('steer', 'drive')),
        ('mecanum', 'mecanum', (0, 1, 2), ('wheel',)),
        ('ur_mecanum', 'mecanum', (0, 1, 2), ('wheel',)),
        ('panda_diff', 'differential', (0, 2), ('wheel',)),
    ],
)
def test_each_shipped_base_answers_for_its_family(robot, family, axes, groups):
    cfg = load_robot(robot)
    base = cfg.base
    assert base.family == family == cfg.raw['base_type'] and base.axes == axes
    assert tuple(base.command_groups) == groups
    section = cfg.raw[family]
    named = section.get('steer_joints', []) + section.get('drive_joints', []) + section.get('wheel_joints', [])
    assert base.joints == tuple(named)
    rolling = section.get('drive_joints') or section['wheel_joints']
    assert base.rolling_joints == tuple(rolling)
    urdf = {j.get('name'): j for j in ET.parse(cfg.urdf_path).getroot().iter('joint')}
    for name in base.joints:  # the YAML's rate limits where it gives them, else the URDF's
        assert cfg.joint_velocity_limits[name] <= float(urdf[name].find('limit').get('velocity'))
    still = [k for k in range(3) if k not in axes]
    assert np.all(base.velocity[still] == 0.0) and np.all(base.velocity[list(axes)] > 0.0)
