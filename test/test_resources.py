"""One package path resolver (``wmm_control.resources``): ``package://``, ``file://`` and relative
mesh paths found in the documented order, by pinocchio, PyBullet and the viewer alike, and a
description whose mesh cannot be found fails in one line that says what to set."""

import numpy as np
import pinocchio as pin
import pybullet as p
import pytest
import yaml

from sim_bridge.world import SimWorld
from urdf_factory import write_box_stl, write_urdf
from wmm_control.cli import robot_setup
from wmm_control.errors import ConfigError
from wmm_control.kinematics.collision import CollisionModel
from wmm_control.resources import check_resources, loadable_urdf, resolve_resource, search_dirs
from wmm_control.robot_config import load_robot
from wmm_control.viewer.scene import RobotScene

CHASSIS = '<box size="0.6 0.45 0.2"/>'
MESH = '<mesh filename="package://made_up_pkg/meshes/box.stl" scale="0.6 0.45 0.2"/>'


@pytest.fixture(autouse=True)
def _no_ros_paths(monkeypatch):
    monkeypatch.delenv('ROS_PACKAGE_PATH', raising=False)
    monkeypatch.delenv('AMENT_PREFIX_PATH', raising=False)


def _mesh_robot(tmp_path):
    """A differential robot whose chassis is a package:// mesh of a made-up package, installed in
    ``tmp_path / 'pkgs'``; returns the URDF path."""
    write_box_stl(tmp_path / 'pkgs' / 'made_up_pkg' / 'meshes' / 'box.stl')
    (tmp_path / 'robot').mkdir()
    urdf = write_urdf(tmp_path / 'robot' / 'r.urdf', 'differential', arm_joints=6)
    urdf.write_text(urdf.read_text().replace(CHASSIS, MESH))
    return urdf


def test_package_uris_are_looked_up_in_the_yaml_folders_then_ros_package_path_then_ament(tmp_path, monkeypatch):
    places = {}
    for where in ('yaml', 'ros', 'ament/share'):
        places[where] = write_box_stl(tmp_path / where / 'pkg' / 'm.stl')
    uri = 'package://pkg/m.stl'
    monkeypatch.setenv('ROS_PACKAGE_PATH', str(tmp_path / 'ros'))
    monkeypatch.setenv('AMENT_PREFIX_PATH', str(tmp_path / 'ament'))
    assert search_dirs([tmp_path / 'yaml']) == [tmp_path / 'yaml', tmp_path / 'ros', tmp_path / 'ament' / 'share']
    assert resolve_resource(uri, tmp_path, search_dirs([tmp_path / 'yaml'])) == places['yaml']
    assert resolve_resource(uri, tmp_path, search_dirs()) == places['ros']
    monkeypatch.delenv('ROS_PACKAGE_PATH')
    assert resolve_resource(uri, tmp_path, search_dirs()) == places['ament/share']
    # a folder that is the package itself, file:// and a path relative to the URDF's folder
    assert resolve_resource(uri, tmp_path, [tmp_path / 'yaml' / 'pkg']) == places['yaml']
    assert resolve_resource(f'file://{places["ros"]}', tmp_path, []) == places['ros']
    assert resolve_resource('ros/pkg/m.stl', tmp_path, []) == places['ros']


def test_an_unknown_package_and_a_missing_file_are_one_line_that_says_what_to_set(tmp_path):
    with pytest.raises(ConfigError) as unknown:
        resolve_resource('package://nowhere_pkg/m.stl', tmp_path, [tmp_path], 'r.urdf')
    text = str(unknown.value)
    assert '\n' not in text and "package 'nowhere_pkg'" in text and 'package_dirs' in text
    assert 'ROS_PACKAGE_PATH' in text and '--package-dir' in text
    (tmp_path / 'pkg').mkdir()
    with pytest.raises(ConfigError, match=r'file missing: .*pkg/m\.stl'):
        resolve_resource('package://pkg/m.stl', tmp_path, [tmp_path], 'r.urdf')


def test_pinocchio_pybullet_and_the_viewer_read_the_same_mesh_from_the_yaml_package_dirs(tmp_path):
    urdf = _mesh_robot(tmp_path)
    with pytest.raises(ConfigError, match="package 'made_up_pkg'"):
        check_resources(urdf)
    out = tmp_path / 'robot' / 'r.yaml'
    robot_setup.init_robot(
        urdf, 'differential', 'arm_base_link', 'tool_link', out, package_dirs=[tmp_path / 'pkgs'], pair_samples=50
    )
    assert yaml.safe_load(out.read_text())['robot']['package_dirs'] == ['../pkgs']
    cfg = load_robot(out)
    assert cfg.package_dirs == ((tmp_path / 'pkgs').resolve(),)
    # pinocchio (the collision model): the chassis is the mesh's convex hull, 0.6 × 0.45 × 0.2 m
    collision = CollisionModel.from_robot(cfg)
    chassis = next(g for g in collision.geom.geometryObjects if g.name.startswith('chassis_link'))
    assert isinstance(chassis.geometry, pin.coal.ConvexBase)
    chassis.geometry.computeLocalAABB()
    extent = np.asarray(chassis.geometry.aabb_local.max_) - np.asarray(chassis.geometry.aabb_local.min_)
    np.testing.assert_allclose(extent, [0.6, 0.45, 0.2], atol=1e-9)
    # the viewer: the same mesh, drawn
    scene = RobotScene(cfg.urdf_path, cfg.base_link, cfg.ee_frame, cfg.package_dirs)
    drawn = next(s for s in scene.shapes if s.name.startswith('chassis_link'))
    assert drawn.kind == 'mesh'
    np.testing.assert_allclose(np.ptp(drawn.vertices, axis=0), [0.6, 0.45, 0.2], atol=1e-9)
    # PyBullet (the simulator): the same mesh file, and the world loads
    loadable = loadable_urdf(cfg.urdf_path, cfg.package_dirs)
    cid = p.connect(p.DIRECT)
    try:
        body = p.loadURDF(str(loadable), physicsClientId=cid)
        joints = range(p.getNumJoints(body, physicsClientId=cid))
        links = {p.getJointInfo(body, j, physicsClientId=cid)[12].decode(): j for j in joints}
        shapes = p.getCollisionShapeData(body, links['chassis_link'], physicsClientId=cid)
        assert shapes[0][2] == p.GEOM_MESH
        assert shapes[0][4].decode() == str(tmp_path / 'pkgs' / 'made_up_pkg' / 'meshes' / 'box.stl')
    finally:
        p.disconnect(cid)
    with SimWorld(cfg) as world:
        assert np.isfinite(world.ee_pose()[0]).all()


def test_check_names_the_missing_package_in_one_line_and_exits_2(tmp_path, capsys):
    urdf = _mesh_robot(tmp_path)
    out = tmp_path / 'robot' / 'r.yaml'
    robot_setup.init_robot(
        urdf, 'differential', 'arm_base_link', 'tool_link', out, package_dirs=[tmp_path / 'pkgs'], pair_samples=50
    )
    raw = yaml.safe_load(out.read_text())
    del raw['robot']['package_dirs']
    out.write_text(yaml.safe_dump(raw))
    capsys.readouterr()
    assert robot_setup.main(['check', str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count('\n') == 0, err
    assert 'package://made_up_pkg/meshes/box.stl' in err and 'package_dirs' in err and 'ROS_PACKAGE_PATH' in err
