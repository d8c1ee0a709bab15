"""Simulated-to-wall time ratio of a 65 s lockstep run of wmm_sim at the 25 ms period.

A controller node in the same process answers every /joint_states message with commands
for every group (the minimum a real controller does). Printed for the kinematic and the
physics base, with the single-threaded and the events executor.
"""

import time

import numpy as np
import rclpy
from rclpy.executors import SingleThreadedExecutor
from rclpy.experimental import EventsExecutor
from rclpy.node import Node
from rclpy.parameter import Parameter
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64MultiArray

from sim_bridge.node import SimNode

SIM_SECONDS = 65.0


class Answerer(Node):
    def __init__(self, context, groups):
        super().__init__('answerer', context=context)
        self.pubs = {
            g: (self.create_publisher(Float64MultiArray, f'/{g}_controller/commands', 10), n) for g, n in groups.items()
        }
        self.last_t = 0.0
        self.create_subscription(JointState, '/joint_states', self.on_state, 10)

    def on_state(self, msg):
        self.last_t = msg.header.stamp.sec + msg.header.stamp.nanosec * 1e-9
        for pub, n in self.pubs.values():
            out = Float64MultiArray()
            out.data = (0.05 * np.sin(self.last_t + np.arange(n))).tolist()
            pub.publish(out)


def run(robot, base_mode, executor_cls):
    ctx = rclpy.Context()
    rclpy.init(context=ctx)
    sim = SimNode(
        context=ctx,
        parameter_overrides=[
            Parameter('timing', value='lockstep'),
            Parameter('robot', value=robot),
            Parameter('base_mode', value=base_mode),
        ],
    )
    groups = {g: len(j) for g, j in sim.world.command_groups.items()}
    ans = Answerer(ctx, groups)
    ex = executor_cls(context=ctx)
    ex.add_node(sim)
    ex.add_node(ans)
    t0 = time.perf_counter()
    while ans.last_t < SIM_SECONDS - 1e-9:
        ex.spin_once(timeout_sec=0.1)
    wall = time.perf_counter() - t0
    ex.shutdown()
    sim.destroy_node()
    ans.destroy_node()
    rclpy.try_shutdown(context=ctx)
    return ans.last_t / wall, wall


def main():
    print(f'{"robot":<10} {"base":<10} {"executor":<16} {"sim/wall":>9} {"wall s":>8}')
    for robot, base_mode in (
        ('steerable', 'kinematic'),
        ('mecanum', 'kinematic'),
        ('steerable', 'physics'),
        ('mecanum', 'physics'),
    ):
        for name, cls in (('SingleThreaded', SingleThreadedExecutor), ('Events', EventsExecutor)):
            ratio, wall = run(robot, base_mode, cls)
            print(f'{robot:<10} {base_mode:<10} {name:<16} {ratio:>8.1f}x {wall:>8.2f}')


if __name__ == '__main__':
    main()
