"""One collision check on a real description, TIAGo (the ``example-robot-data`` wheel), with its
hand and without: its collision meshes as triangle soups (coal's ``BVHModel``, as pinocchio
loads them) and as their convex hulls (what the collision model takes,
``wmm_control.kinematics.collision.collision_geometry``), in the same run. Prints figures,
asserts nothing.

For each description: ``wmm_robot init`` as docs/robots.md gives it (the pairs chosen on the
hulls), then one ``CollisionModel.within`` at the influence distance (0.10 m), the safety
stage's call each cycle, at the same seeded random arm postures for the two geometries, taken
in turn posture by posture so that whatever else loads the machine falls on both alike; the
floor included and the start state's contacts left out, as the controller builds the model;
for the pairs ``init`` chose and for the default rules (no ``collision.pairs``). Each of those
models has a kinematic model of its own, which each check updates to its posture. The hulls'
check is then timed as a cycle makes it, on the method's kinematic model after the method's
update (timed apart: the check reads its joint placements and Jacobians), in turn with the
same check on a kinematic model of its own. Also: how
``init`` chooses the pairs on each geometry, and the deepest overlap seen (a triangle soup
never reports one).

    python benchmarks/bench_collision.py [--postures 200] [--seed 1]
"""

import argparse
import functools
import sys
import tempfile
import time
from pathlib import Path
from unittest import mock

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))  # run from a source checkout
sys.path.insert(0, str(ROOT / 'benchmarks'))  # the benchmarks' shared code

from shared import TIAGO, set_up_tiago  # noqa: E402
from wmm_control.kinematics import collision  # noqa: E402
from wmm_control.kinematics.collision import CollisionModel, choose_pairs  # noqa: E402
from wmm_control.kinematics.model import KinematicModel  # noqa: E402
from wmm_control.robot_config import load_robot  # noqa: E402

INFLUENCE = 0.10
GEOMETRIES = ('triangle meshes', 'convex hulls')


def build(geometry, *args, **kwargs):
    """``CollisionModel(*args, **kwargs)`` on ``geometry`` (one of :data:`GEOMETRIES`)."""
    if geometry == GEOMETRIES[1]:
        return CollisionModel(*args, **kwargs)
    with mock.patch.object(collision, 'convex_hulls', lambda shapes: 0):  # the meshes as pinocchio loads them
        return CollisionModel(*args, **kwargs)


def choose(geometry, cfg):
    """``choose_pairs`` as ``init`` calls it, on ``geometry``."""
    call = (cfg.urdf_path, cfg.arm.joints, cfg.ground_z)
    if geometry == GEOMETRIES[1]:
        return choose_pairs(*call, package_dirs=cfg.package_dirs)
    with mock.patch.object(collision, 'convex_hulls', lambda shapes: 0):
        return choose_pairs(*call, package_dirs=cfg.package_dirs)


def bench(name, postures, seed, folder):
    start = time.perf_counter()
    out = set_up_tiago(name, folder)
    print(f'== {TIAGO[name]}: init {time.perf_counter() - start:.1f} s')
    cfg = load_robot(out)
    checked = []
    for geometry in GEOMETRIES:
        start = time.perf_counter()
        choice = choose(geometry, cfg)
        checked.append(choice.checked)
        counts = ' / '.join(str(len(choice.left_out[r])) for r in ('adjacent', 'rigid', 'always', 'never'))
        print(
            f'  pairs chosen on {geometry}: {choice.candidates} candidates, left out adjacent / rigid / always / '
            f'never {counts}, {len(choice.checked)} checked ({time.perf_counter() - start:.1f} s)'
        )
    print(f'  the same pairs on both: {checked[0] == checked[1]}')
    arm = cfg.arm
    lower, upper = np.maximum(arm.position_lower, -np.pi), np.minimum(arm.position_upper, np.pi)
    q_arms = lower + (upper - lower) * np.random.default_rng(seed).random((postures, arm.n))
    for rule, pairs in (('chosen pairs', cfg.collision_pairs), ('default rules', None)):
        models = [
            build(g, cfg.urdf_path, arm.joints, cfg.ground_z, cfg.start.arm, pairs=pairs, package_dirs=cfg.package_dirs)
            for g in GEOMETRIES
        ]
        times = np.zeros((len(models), postures))
        closest = np.full(len(models), np.inf)
        for i, q in enumerate(q_arms):
            for k, model in enumerate(models):
                t0 = time.perf_counter()
                _, distance, _ = model.within(q, INFLUENCE, np.zeros(3))
                times[k, i] = time.perf_counter() - t0
                closest[k] = min(closest[k], distance)
        for geometry, model, row, deepest in zip(GEOMETRIES, models, times, closest):
            print(
                f'  {rule}, {geometry}: {len(model.pairs)} shape pairs; one check median '
                f'{np.median(row) * 1e3:.2f} ms, p90 {np.percentile(row, 90) * 1e3:.2f} ms, max '
                f'{row.max() * 1e3:.2f} ms; closest over the postures {deepest * 1e3:.1f} mm'
            )
        shared(cfg, pairs, rule, q_arms)


def shared(cfg, pairs, rule, q_arms):
    """The hulls' check as the safety stage makes it in a cycle, on the method's kinematic model
    after the method's update at the posture (the update timed apart: the check reads its joint
    placements and Jacobians), in turn posture by posture with the same check on a kinematic
    model of its own (which the check updates)."""
    kinematics = KinematicModel(cfg)
    build = functools.partial(
        CollisionModel,
        cfg.urdf_path,
        cfg.arm.joints,
        cfg.ground_z,
        cfg.start.arm,
        pairs=pairs,
        package_dirs=cfg.package_dirs,
    )
    alone, on_method = build(), build(kinematics=kinematics)
    times = np.zeros((3, len(q_arms)))
    for i, q in enumerate(q_arms):
        t0 = time.perf_counter()
        alone.within(q, INFLUENCE, np.zeros(3))
        t1 = time.perf_counter()
        kinematics.update(np.zeros(3), q)
        t2 = time.perf_counter()
        on_method.within(q, INFLUENCE, np.zeros(3))
        times[:, i] = t1 - t0, t2 - t1, time.perf_counter() - t2
    alone_ms, update_ms, shared_ms = np.median(times, axis=1) * 1e3
    print(
        f'  {rule}, convex hulls: one check with its own update median {alone_ms:.3f} ms; after the '
        f"method's update ({update_ms:.3f} ms) {shared_ms:.3f} ms"
    )


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--postures', type=int, default=200)
    parser.add_argument('--seed', type=int, default=1)
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as folder:
        for name in TIAGO:
            bench(name, args.postures, args.seed, folder)


if __name__ == '__main__':
    main()
