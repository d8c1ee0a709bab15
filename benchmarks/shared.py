"""What several benchmarks share (not a benchmark itself: ``dev.sh bench`` runs ``bench_*.py``).

- :class:`PinkStep`: one differential-IK step of pink (``pin-pink`` with the quadprog solver; a
  frame task on the end effector and a posture task, optionally pink's
  ``SelfCollisionBarrier``) on a shipped robot's model, the yardstick of a QP-based
  whole-body IK. pink is installed for the benchmarks only (``bash scripts/dev.sh bench``);
  :func:`pink_installed` says whether it is there.
- :func:`bench_pink`: that step's wall time while it tracks a moving target.
- :func:`closed_loop_states`: the states of a closed-loop run (direct engine) through a goal
  in the arm's reach and one that needs the base, to replay through a method.
- :func:`set_up_tiago`: PAL's TIAGo from the ``example-robot-data`` wheel, set up with
  ``wmm_robot init`` as docs/robots.md gives it (:data:`TIAGO` names its two descriptions).
"""

import importlib.util
import time
from importlib.metadata import PackageNotFoundError, distribution
from pathlib import Path

import numpy as np
import pinocchio as pin

from wmm_control.kinematics import KinematicModel
from wmm_control.kinematics.collision import FLOOR, CollisionModel, collision_geometry
from wmm_control.geometry import matrix_from_quaternion
from wmm_control.resolvers import PoseTarget, make_resolver
from wmm_control.robot_config import load_robot

__all__ = [
    'PinkStep',
    'pink_installed',
    'bench_pink',
    'closed_loop_states',
    'OFFSETS',
    'TIAGO',
    'tiago_share',
    'set_up_tiago',
]

#: The two goals of :func:`closed_loop_states`, from the start pose of the end effector [m]:
#: one within the arm's reach, one that needs the base.
OFFSETS = (np.array([0.1, 0.05, -0.05]), np.array([1.5, -1.0, 0.0]))


#: TIAGo's descriptions in the example-robot-data wheel, by the names the benchmarks give them:
#: with its Hey5 hand, and without.
TIAGO = {'tiago': 'tiago.urdf', 'tiago_no_hand': 'tiago_no_hand.urdf'}


def tiago_share() -> Path | None:
    """The ``share`` folder of the example-robot-data wheel (it holds example-robot-data/robots/…);
    None when the wheel is not installed."""
    try:
        return Path(str(distribution('example-robot-data').locate_file('cmeel.prefix/share')))
    except PackageNotFoundError:
        return None


def set_up_tiago(name, folder) -> Path:
    """``wmm_robot init`` of TIAGo's description ``name`` (a key of :data:`TIAGO`) as
    docs/robots.md gives it, written to ``folder``/<name>.yaml; returns that path."""
    from wmm_control.cli.robot_setup import init_robot

    share = tiago_share()
    if share is None:
        raise SystemExit('TIAGo needs the example-robot-data wheel (pip install example-robot-data)')
    urdf = share / 'example-robot-data' / 'robots' / 'tiago_description' / 'robots' / TIAGO[name]
    out = Path(folder) / f'{name}.yaml'
    init_robot(urdf, 'differential', 'torso_fixed_link', 'arm_tool_link', out, package_dirs=[share])
    return out


def pink_installed() -> bool:
    """True when pink and quadprog can be imported."""
    return all(importlib.util.find_spec(name) is not None for name in ('pink', 'quadprog'))


class PinkStep:
    """One pink IK step on ``robot``'s model (:class:`~wmm_control.kinematics.KinematicModel`:
    the base's (x, y, θ) and the arm's joints), posture task at the start state.

    With ``barrier``, pink's ``SelfCollisionBarrier`` over the robot's own pairs: the URDF's
    collision shapes (meshes as their convex hulls, as the package's) on the same model, the pairs of shapes the package's
    :class:`~wmm_control.kinematics.collision.CollisionModel` checks (those touching at the
    start posture left out), without the floor (pink has none), every pair's distance each step.
    """

    def __init__(self, robot='steerable', barrier=False, dt=0.025):
        import pink
        from pink.barriers import SelfCollisionBarrier
        from pink.tasks import FrameTask, PostureTask

        self._pink = pink
        cfg = load_robot(robot)
        self.kinematics = km = KinematicModel(cfg)
        self.dt = dt
        q0 = self.configuration(cfg.start.base_pose, cfg.start.arm)
        geometry = {}
        self.barriers = []
        if barrier:
            geom = collision_geometry(km.model, cfg.urdf_path, cfg.package_dirs)
            # every pair of shapes the package checks (within an infinite distance), the floor's
            # left out: pink has no floor
            near, _, _ = CollisionModel.from_robot(cfg).within(cfg.start.arm, np.inf, cfg.start.base_pose)
            checked = {frozenset(pair) for pair in near.shapes if FLOOR not in pair}
            names = [g.name for g in geom.geometryObjects]
            for a in range(len(names)):
                for b in range(a + 1, len(names)):
                    if frozenset((names[a], names[b])) in checked:
                        geom.addCollisionPair(pin.CollisionPair(a, b))
            geometry = {'collision_model': geom, 'collision_data': pin.GeometryData(geom)}
            self.barriers = [SelfCollisionBarrier(len(geom.collisionPairs))]
        self.pairs = len(geometry['collision_model'].collisionPairs) if barrier else 0
        self.conf = pink.Configuration(km.model, km.model.createData(), q0, **geometry)
        self.ee = FrameTask(km.ee_frame, position_cost=1.0, orientation_cost=1.0)
        posture = PostureTask(cost=1e-3)
        posture.set_target(q0)
        self.tasks = [self.ee, posture]

    def configuration(self, base_pose, q_arm) -> np.ndarray:
        """pinocchio's configuration of the base pose (x, y, θ) and the arm joints."""
        return self.kinematics.configuration(base_pose, q_arm)[0]

    def update(self, q) -> None:
        """pink's ``Configuration.update``: kinematics, and with the barrier every pair's distance."""
        self.conf.update(q)

    def set_target(self, position, rotation) -> None:
        """The end-effector task's target pose (``position``, ``rotation``), world frame."""
        self.ee.set_target(pin.SE3(np.asarray(rotation, dtype=float), np.asarray(position, dtype=float)))

    def solve(self) -> np.ndarray | None:
        """pink's ``solve_ik``: the joint velocity of this step; None when its QP has no solution
        (pink's ``NoSolutionFound``: the barrier's rows conflict at some states)."""
        from pink.exceptions import NoSolutionFound

        try:
            return self._pink.solve_ik(self.conf, self.tasks, self.dt, solver='quadprog', barriers=self.barriers)
        except NoSolutionFound:
            return None


def bench_pink(cycles, robot='steerable'):
    """Wall time [µs] of ``solve_ik`` per cycle on ``robot``, tracking a moving end-effector
    target from the start state (the configuration integrated between the cycles, untimed);
    None when pink is not installed."""
    if not pink_installed():
        return None
    step = PinkStep(robot)
    start = step.conf.get_transform_frame_to_world(step.kinematics.ee_frame).copy()
    times = []
    for k in range(cycles + 50):
        offset = np.array([0.3 * np.sin(0.01 * k), 0.2 * np.cos(0.01 * k), 0.0])
        step.set_target(start.translation + offset, start.rotation)
        t0 = time.perf_counter()
        v = step.solve()
        times.append((time.perf_counter() - t0) * 1e6)
        step.conf.integrate_inplace(v, step.dt)
    return np.array(times[50:])


def closed_loop_states(cfg, cycles):
    """``(state, target, base reference)`` of ``cycles`` periods of an AMP run (direct engine,
    no obstacles) through both :data:`OFFSETS` goals: the first third towards the goal in reach."""
    from sim_bridge.closed_loop import ClosedLoop
    from sim_bridge.world import SimWorld

    out = []
    with SimWorld(cfg) as world:
        loop = ClosedLoop(world, make_resolver('amp', cfg))
        p0, q0 = world.ee_pose()
        for k in range(cycles):
            target = PoseTarget(np.asarray(p0) + OFFSETS[0 if k < cycles // 3 else 1], matrix_from_quaternion(q0))
            state = loop.state()
            rec = loop.step(target)
            out.append((state, target, rec.command.base_twist))
    return out
