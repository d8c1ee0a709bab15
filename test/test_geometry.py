"""The geometry module: planar poses and twists, rotations, angle wrapping, continuous joints
and scaling into limits, each against its definition or an independent construction."""

import math

import numpy as np
import pinocchio as pin
import pytest
from hypothesis import given, settings, strategies as st

from wmm_control.geometry import (
    angles_to_pin_q,
    cap_norm,
    continuous_from_q,
    continuous_to_q,
    largest_step,
    matrix_from_rpy,
    norm,
    rotation_2d,
    rotation_angle,
    rotation_error,
    rotation_z,
    scale_into_limits,
    se2_compose,
    se2_integrate,
    se2_twist,
    se2_inverse,
    se2_transform_points,
    se3_from_planar,
    twist_to_base,
    twist_to_world,
    wrap_angle,
)

angles = st.floats(-20.0, 20.0)
poses = st.tuples(st.floats(-5, 5), st.floats(-5, 5), angles)
twists = st.tuples(st.floats(-2, 2), st.floats(-2, 2), st.floats(-3, 3))


def _se3(pose):
    """An independent SE(3) of a planar pose: pinocchio's RPY with zero roll and pitch."""
    return pin.SE3(pin.rpy.rpyToMatrix(0.0, 0.0, pose[2]), np.array([pose[0], pose[1], 0.0]))


def _planar(placement):
    return np.array([placement.translation[0], placement.translation[1], pin.rpy.matrixToRpy(placement.rotation)[2]])


@settings(max_examples=200, deadline=None)
@given(st.floats(-1e4, 1e4))
def test_wrap_angle_lands_in_the_half_open_interval_and_differs_by_whole_turns(angle):
    for period in (2 * math.pi, math.pi):
        w = wrap_angle(angle, period)
        assert -period / 2 < w <= period / 2
        turns = (angle - w) / period
        assert abs(turns - round(turns)) < 1e-9
    assert wrap_angle(math.pi) == math.pi and wrap_angle(-math.pi) == math.pi
    assert wrap_angle(-math.pi / 2, math.pi) == math.pi / 2
    np.testing.assert_allclose(wrap_angle(np.array([3 * math.pi, -0.5])), [math.pi, -0.5])
    # a scalar exactly, as math.remainder (the planners' headings and turns), an array to round-off
    assert wrap_angle(angle) in (math.remainder(angle, 2 * math.pi), math.pi)
    assert abs(math.remainder(wrap_angle(np.array([angle]))[0] - wrap_angle(angle), 2 * math.pi)) < 1e-11
    assert wrap_angle(1e-17) == 1e-17 and wrap_angle(np.float64(-1e-17)) == -1e-17


@settings(max_examples=100, deadline=None)
@given(poses, poses)
def test_se2_compose_and_inverse_are_those_of_the_placements(a, b):
    got, want = se2_compose(a, b), _planar(_se3(a) * _se3(b))
    np.testing.assert_allclose(got[:2], want[:2], atol=1e-9)
    assert abs(wrap_angle(got[2] - want[2])) < 1e-9
    inv, want = se2_inverse(a), _planar(_se3(a).inverse())
    np.testing.assert_allclose(inv[:2], want[:2], atol=1e-9)
    assert abs(wrap_angle(inv[2] - want[2])) < 1e-9
    np.testing.assert_allclose(se2_compose(a, inv)[:2], 0.0, atol=1e-9)
    point = np.array([b[0], b[1]])
    np.testing.assert_allclose(se2_transform_points(a, point), (_se3(a) * np.array([*point, 0.0]))[:2], atol=1e-9)
    there = se2_transform_points(a, np.array([point, 2 * point]))
    np.testing.assert_allclose(se2_transform_points(inv, there), [point, 2 * point], atol=1e-8)
    np.testing.assert_allclose(se3_from_planar(a).homogeneous, _se3(a).homogeneous, atol=1e-12)


@settings(max_examples=100, deadline=None)
@given(angles, twists)
def test_twists_turn_between_the_base_and_the_world(theta, twist):
    world = twist_to_world(theta, twist)
    expected = pin.rpy.rpyToMatrix(0.0, 0.0, theta) @ np.array([twist[0], twist[1], 0.0])
    np.testing.assert_allclose(world[:2], expected[:2], atol=1e-12)
    assert world[2] == twist[2]
    np.testing.assert_allclose(twist_to_base(theta, world), twist, atol=1e-12)
    stack = twist_to_world(theta, np.array([twist, twist]))
    np.testing.assert_allclose(stack, [world, world], atol=1e-15)
    np.testing.assert_allclose(rotation_z(theta)[:2, :2], rotation_2d(theta), atol=0)
    np.testing.assert_allclose(rotation_z(theta), pin.rpy.rpyToMatrix(0.0, 0.0, theta), atol=1e-15)


@settings(max_examples=100, deadline=None)
@given(poses, twists, st.floats(0.01, 3.0))
def test_se2_integrate_is_exact_for_a_constant_twist(pose, twist, dt):
    """One step equals many small ones, and equals the rotation about the ICR (or the straight
    line of a pure translation)."""
    one = se2_integrate(pose, twist, dt)
    many = pose
    for _ in range(40):
        many = se2_integrate(many, twist, dt / 40)
    np.testing.assert_allclose(one, many, atol=1e-9)
    x, y, th = pose
    vx, vy, w = twist
    assert one[2] == pytest.approx(th + w * dt, abs=1e-12)
    if abs(w) > 1e-3:
        icr = np.array([x, y]) + rotation_2d(th) @ [-vy / w, vx / w]
        np.testing.assert_allclose(one[:2], icr + rotation_2d(w * dt) @ (np.array([x, y]) - icr), atol=1e-9)
    if abs(w * dt) < 3.0:  # the twist back from the two poses (the SE(2) log)
        np.testing.assert_allclose(se2_twist(pose, one, dt), twist, atol=1e-9)
    np.testing.assert_allclose(
        se2_integrate((x, y, th), (vx, vy, 0.0), dt)[:2],
        np.array([x, y]) + rotation_2d(th) @ [vx * dt, vy * dt],
        atol=1e-12,
    )


@settings(max_examples=100, deadline=None)
@given(st.lists(st.floats(-3, 3), min_size=3, max_size=3), st.lists(st.floats(-3, 3), min_size=3, max_size=3))
def test_rotation_error_is_the_rotation_vector_between_orientations(rpy_a, rpy_b):
    ra, rb = matrix_from_rpy(rpy_a), matrix_from_rpy(rpy_b)
    err = rotation_error(ra, rb)
    assert np.linalg.norm(err) <= math.pi + 1e-12
    np.testing.assert_allclose(pin.exp3(err) @ rb, ra, atol=1e-9)
    assert rotation_angle(ra, rb) == pytest.approx(np.linalg.norm(err), abs=1e-15)
    np.testing.assert_allclose(rotation_error([ra, rb], [rb, rb]), [err, np.zeros(3)], atol=1e-12)
    assert rotation_error(np.zeros((0, 3, 3)), np.zeros((0, 3, 3))).shape == (0, 3)


@settings(max_examples=100, deadline=None)
@given(st.floats(-50, 50))
def test_continuous_joints_round_trip_through_cos_and_sin(angle):
    c, s = continuous_to_q(angle)
    assert c == pytest.approx(math.cos(angle)) and s == pytest.approx(math.sin(angle))
    assert (
        continuous_from_q(c, s) == pytest.approx(wrap_angle(angle), abs=1e-9)
        or abs(abs(wrap_angle(angle)) - math.pi) < 1e-9
    )
    arr = continuous_to_q(np.array([angle, 0.0]))
    np.testing.assert_allclose(continuous_from_q(*arr)[1], 0.0)


def test_angles_to_pin_q_places_continuous_and_plain_joints(tmp_path):
    model = pin.Model()
    j1 = model.addJoint(0, pin.JointModelRUBZ(), pin.SE3.Identity(), 'wheel')  # continuous: nq 2, nv 1
    model.addJoint(j1, pin.JointModelRZ(), pin.SE3.Identity(), 'arm')
    q = angles_to_pin_q(model, [0.4, -1.2])
    np.testing.assert_allclose(q, [math.cos(0.4), math.sin(0.4), -1.2])
    data = model.createData()
    pin.forwardKinematics(model, data, q)
    assert pin.rpy.matrixToRpy(data.oMi[2].rotation)[2] == pytest.approx(0.4 - 1.2)


@settings(max_examples=200, deadline=None)
@given(
    st.lists(st.floats(-1e300, 1e300), min_size=3, max_size=3),
    st.lists(st.floats(0.01, 10.0), min_size=3, max_size=3),
)
def test_scale_into_limits_keeps_the_direction_and_the_largest_fitting_size(vec, limits):
    vec, limits = np.array(vec), np.array(limits)
    out, s = scale_into_limits(vec, limits)
    assert 0.0 <= s <= 1.0 and np.all(np.isfinite(out))
    assert np.all(np.abs(out) <= limits)
    if s == 1.0:
        np.testing.assert_array_equal(out, vec)
    else:
        assert np.max(np.abs(out) / limits) == pytest.approx(1.0, rel=1e-12)  # the largest that fits
        peak = np.max(np.abs(vec))
        np.testing.assert_allclose(out / np.max(np.abs(out)), vec / peak, atol=1e-12)  # same direction
    rows = np.array([[1.0, 1.0, 0.0], [0.0, 2.0, -1.0]])
    out, s = scale_into_limits(vec, limits[:2], rows)
    assert np.all(np.abs(rows @ out) <= limits[:2] * (1 + 1e-12))


@settings(max_examples=200, deadline=None)
@given(st.lists(st.floats(-1e300, 1e300), min_size=1, max_size=6), st.floats(0.1, 10.0))
def test_cap_norm_and_norm_do_not_overflow(vec, limit):
    vec = np.array(vec)
    capped = cap_norm(vec, limit)
    n = norm(vec)
    assert math.isfinite(n) or np.max(np.abs(vec)) > 1e154
    assert norm(capped) <= limit * (1 + 1e-12)
    if norm(vec) <= limit:
        np.testing.assert_array_equal(capped, vec)
    elif np.any(vec):
        unit = vec / np.max(np.abs(vec))
        np.testing.assert_allclose(capped / norm(capped), unit / norm(unit), rtol=0, atol=1e-12)


@settings(max_examples=200, deadline=None)
@given(
    st.lists(st.floats(-1, 1), min_size=5, max_size=5),
    st.lists(st.floats(-5, 5), min_size=5, max_size=5),
    st.lists(st.booleans(), min_size=5, max_size=5),
)
def test_largest_step_is_the_largest_that_stays_within_the_bounds(start, step, mask):
    start, step, mask = np.array(start), np.array(step), np.array(mask)
    lower, upper = np.full(5, -1.0), np.full(5, 1.0)
    s, per = largest_step(start, step, lower, upper, mask)
    assert 0.0 <= s <= 1.0
    end = start + s * step
    assert np.all((end[mask] >= -1 - 1e-12) & (end[mask] <= 1 + 1e-12))
    if s < 1.0:  # an entry that binds ends on its bound, moving outwards
        binding = mask & (per <= s + 1e-12)
        assert np.any(np.isclose(np.abs(end[binding]), 1.0, rtol=0, atol=1e-9) & (end[binding] * step[binding] > 0))
    assert np.all(per[~mask] == np.inf)
