"""Collision pairs chosen as MoveIt's set-up assistant does (``choose_pairs``): adjacent links,
links no arm joint moves apart, pairs always in contact or never near, and an SRDF's
``disable_collisions`` left out; ``init`` writes the rest into the robot YAML, the collision
model checks exactly those, and ``init`` and ``check`` print their number and cost."""

import numpy as np
import pytest
import yaml

from urdf_factory import write_urdf
from wmm_control.cli import robot_setup
from wmm_control.kinematics.collision import FLOOR, CollisionModel, choose_pairs
from wmm_control.robot_config import load_robot
from wmm_control.urdf import UrdfTree

ARM6 = [f'arm_joint_{k}' for k in range(1, 7)]


@pytest.fixture(scope='module')
def robot(tmp_path_factory):
    """A made-up differential robot with a second, rigid shape on the tool link's parent."""
    urdf = write_urdf(tmp_path_factory.mktemp('pairs') / 'r.urdf', 'differential', arm_joints=6)
    # a camera fixed to the chassis: rigid with the body, adjacent to the chassis
    urdf.write_text(
        urdf.read_text().replace(
            '</robot>',
            '<joint name="camera_joint" type="fixed"><parent link="chassis_link"/><child link="camera_link"/>'
            '<origin xyz="-0.2 0 0.3"/></joint><link name="camera_link"><inertial><mass value="0.1"/>'
            '<inertia ixx="0.001" iyy="0.001" izz="0.001" ixy="0" ixz="0" iyz="0"/></inertial>'
            '<collision><geometry><box size="0.05 0.05 0.05"/></geometry></collision></link></robot>',
        )
    )
    return urdf


def _distances(urdf, pairs, postures, ground_z=None):
    """Each link pair's distance at each arm posture: shape (postures, pairs)."""
    model = CollisionModel(urdf, ARM6, ground_z, margin=-np.inf, pairs=pairs)
    index = {frozenset(pair): k for k, pair in enumerate(pairs)}
    out = np.full((len(postures), len(pairs)), np.inf)
    for i, q in enumerate(postures):
        dists = model._distances(model._configuration(q))
        for links, d in zip(model.pairs, dists):
            k = index[frozenset(links)]
            out[i, k] = min(out[i, k], d)
    return out


def _init(urdf, out):
    """``wmm_robot init`` of the made-up differential robot, checked to succeed: ``out``."""
    args = ['init', str(urdf), '--base', 'differential', '--arm-root', 'arm_base_link', '--tool', 'tool_link']
    assert robot_setup.main(args + ['--out', str(out)]) == 0
    return out


def test_every_left_out_pair_is_left_out_for_its_reason(robot):
    choice = choose_pairs(robot, ARM6, ground_z=0.0, influence=0.1, samples=300)
    tree = UrdfTree(robot)
    shaped = [n for n, e in tree.links.items() if e.find('collision') is not None]
    n = len(shaped) + 1  # and the floor
    assert choice.candidates == n * (n - 1) // 2
    assert choice.candidates == len(choice.checked) + sum(len(v) for v in choice.left_out.values())
    rng = np.random.default_rng(7)
    postures = rng.uniform(-2.6, 2.6, (40, 6))
    # rigid: their distance never changes, whatever the arm does
    rigid = list(choice.left_out['rigid'])
    assert {frozenset(('camera_link', 'wheel_left_link')), frozenset(('camera_link', 'floor'))} <= set(
        map(frozenset, rigid)
    )
    assert frozenset(('camera_link', 'chassis_link')) in set(map(frozenset, choice.left_out['adjacent']))
    robot_rigid = [pair for pair in rigid if FLOOR not in pair]
    d = _distances(robot, robot_rigid, postures, ground_z=0.0)
    np.testing.assert_allclose(d, np.broadcast_to(d[0], d.shape), atol=1e-9)
    # adjacent: one hangs from the other in the URDF's tree
    parent = {j.child: j.parent for j in tree.joints.values()}

    def shaped_above(link):
        link = parent.get(link)
        while link is not None and link not in shaped:
            link = parent.get(link)
        return link

    assert choice.left_out['adjacent']
    for a, b in choice.left_out['adjacent']:
        assert shaped_above(a) == b or shaped_above(b) == a
    # the checked pairs all come within the influence distance, and get apart, at some posture
    d = _distances(robot, list(choice.checked), rng.uniform(-2.6, 2.6, (300, 6)), ground_z=0.0)
    assert (d.min(axis=0) < 0.1).mean() > 0.5
    assert np.all(d.max(axis=0) > 1e-3)
    # the body and the floor are never a pair: nothing moves them apart
    assert all(not {'chassis_link', FLOOR} <= set(pair) for pair in choice.checked)


def test_an_srdf_leaves_its_pairs_out(robot, tmp_path):
    first = choose_pairs(robot, ARM6, ground_z=0.0, samples=100).checked
    srdf = tmp_path / 'r.srdf'
    srdf.write_text(
        '<robot name="made_up">'
        + ''.join(f'<disable_collisions link1="{a}" link2="{b}" reason="Never"/>' for a, b in first[:3])
        + '</robot>'
    )
    choice = choose_pairs(robot, ARM6, ground_z=0.0, samples=100, srdf=srdf)
    assert sorted(choice.left_out['srdf']) == sorted(first[:3])
    assert set(choice.checked) == set(first[3:])


def test_init_writes_the_pairs_the_collision_model_then_checks_and_prints_their_cost(robot, tmp_path, capsys):
    out = _init(robot, tmp_path / 'r.yaml')
    printed = capsys.readouterr().out
    written = yaml.safe_load(out.read_text())['robot']['collision']['pairs']
    cfg = load_robot(out)
    assert cfg.collision_pairs == tuple(tuple(pair) for pair in written)
    model = CollisionModel.from_robot(cfg, margin=-np.inf)
    assert {frozenset(pair) for pair in model.pairs} == {frozenset(pair) for pair in written}
    assert f'{len(model.pairs)} shape pairs checked' in printed and 'ms (median of' in printed
    # an edit of the list is what the model checks
    raw = yaml.safe_load(out.read_text())
    raw['robot']['collision']['pairs'] = written[:2]
    out.write_text(yaml.safe_dump(raw))
    edited = CollisionModel.from_robot(load_robot(out), margin=-np.inf)
    assert {frozenset(pair) for pair in edited.pairs} == {frozenset(pair) for pair in written[:2]}
    assert robot_setup.main(['check', str(out)]) == 0
    assert '2 shape pairs checked (2 link pairs, from collision.pairs of the YAML)' in capsys.readouterr().out


def test_check_warns_when_one_distance_check_exceeds_the_budget(monkeypatch, capsys):
    monkeypatch.setattr(robot_setup, 'CHECK_BUDGET', 1e-9)
    assert robot_setup.main(['check', 'panda_diff']) == 0
    captured = capsys.readouterr()
    assert 'from the default rules' in captured.out
    assert captured.err.startswith('warning: one distance check takes') and 'budget' in captured.err


def _box(size, xyz):
    return f'<collision><origin xyz="{xyz}"/><geometry><box size="{size}"/></geometry></collision>'


def test_two_links_that_rest_close_on_one_shape_pair_and_meet_on_another_are_checked(tmp_path, capsys):
    """A collar fixed to the arm's mount rests 1 cm from the first arm link's round shape (at
    every angle of the first joint, which turns that shape about its own axis), and the
    collar's post stands where that link's paddle sweeps through. The link pair is no
    ``always`` pair: it is checked, with the shape pair that rests close left out at the start
    posture, and init still finds a start posture of its own."""
    urdf = write_urdf(tmp_path / 'r.urdf', 'differential', arm_joints=6)
    text = urdf.read_text()
    # the first arm link's cylinder: radius 0.035 about the joint's axis, z 0.13–0.22 in the mount's
    # frame; a paddle along x, z 0.195–0.215, swept round by the first joint
    paddle = _box('0.115 0.02 0.02', '0.0925 0 0.105')
    marker = '<link name="arm_link_1">'
    start = text.index(marker)
    end = text.index('</link>', start)
    text = text[:end] + paddle + text[end:]
    collar = (
        '<joint name="collar_joint" type="fixed"><parent link="arm_base_link"/><child link="collar_link"/>'
        '<origin xyz="0 0 0"/></joint><link name="collar_link"><inertial><mass value="0.1"/>'
        '<inertia ixx="0.001" iyy="0.001" izz="0.001" ixy="0" ixz="0" iyz="0"/></inertial>'
        + _box('0.02 0.02 0.02', '0.055 0 0.145')  # 1 cm from the cylinder, 4 cm below the paddle
        + _box('0.02 0.02 0.06', '0 0.1 0.205')  # the post, in the paddle's sweep at +90°
        + '</link></robot>'
    )
    urdf.write_text(text.replace('</robot>', collar))
    pair = frozenset(('collar_link', 'arm_link_1'))
    choice = choose_pairs(urdf, ARM6, ground_z=0.0, samples=300)
    assert pair in set(map(frozenset, choice.checked))
    assert pair not in set(map(frozenset, choice.left_out['always']))
    out = _init(urdf, tmp_path / 'r.yaml')
    capsys.readouterr()
    cfg = load_robot(out)
    assert pair in {frozenset(p) for p in cfg.collision_pairs}
    model = CollisionModel.from_robot(cfg)
    checked = {frozenset(shapes) for shapes in model._pair_shapes}
    # the resting pair is left out at the start posture, the post and the paddle are checked
    assert frozenset(('collar_link_0', 'arm_link_1_0')) not in checked
    assert frozenset(('collar_link_1', 'arm_link_1_1')) in checked
    # turned onto the post, the model sees the contact
    q = np.array(cfg.start.arm, dtype=float)
    q[0] = np.pi / 2
    d, names = model.closest(q)
    assert d < 0.0 and frozenset(names) == pair
