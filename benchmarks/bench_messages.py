"""Where a node-engine period goes: each subscription's callback and each publish, per topic.

Runs one run of the Table II experiment (``sorour_table2``, default ``pinv``) with every node
in this process (the nodes engine of ``wmm_experiment``), with every subscription callback and
every ``publish`` of every node timed (rclpy's ``Node.create_subscription`` and
``create_publisher`` wrapped for this process only). Prints, per control period: the wall
time, each topic's deliveries and callback time (the node's own work, the maths included),
each topic's publishes and their time, and what is left: the executor taking the messages
from the middleware and turning them into Python objects.

Usage::

    python benchmarks/bench_messages.py [--run pinv]
"""

import argparse
import collections
import time

import rclpy.node

from wmm_control.cli.experiment import run_experiment
from wmm_control.experiments.scenario import load_scenario

SCENARIO = 'sorour_table2'


class Timings:
    """Calls and seconds per (node, topic), for callbacks and for publishes."""

    def __init__(self):
        self.calls = collections.Counter()
        self.seconds = collections.Counter()

    def timed(self, key, fn):
        def wrapper(*args):
            start = time.perf_counter()
            out = fn(*args)
            self.seconds[key] += time.perf_counter() - start
            self.calls[key] += 1
            return out

        return wrapper


def instrument():
    """Wrap every node's subscriptions and publishers created from now on; returns the timings
    (callbacks, publishes)."""
    callbacks, publishes = Timings(), Timings()
    create_subscription, create_publisher = rclpy.node.Node.create_subscription, rclpy.node.Node.create_publisher

    def subscription(self, msg_type, topic, callback, *args, **kwargs):
        key = (self.get_name(), topic)
        return create_subscription(self, msg_type, topic, callbacks.timed(key, callback), *args, **kwargs)

    def publisher(self, msg_type, topic, *args, **kwargs):
        pub = create_publisher(self, msg_type, topic, *args, **kwargs)
        pub.publish = publishes.timed((self.get_name(), topic), pub.publish)
        return pub

    rclpy.node.Node.create_subscription = subscription
    rclpy.node.Node.create_publisher = publisher
    return callbacks, publishes


def report(title, timings, periods):
    print(f'  {title:<58}{"per period":>11}{"µs/period":>11}')
    total = 0.0
    for key in sorted(timings.seconds, key=lambda k: -timings.seconds[k]):
        per = timings.seconds[key] / periods * 1e6
        total += per
        if timings.calls[key] / periods >= 0.05:
            print(f'  {key[0] + " " + key[1]:<58}{timings.calls[key] / periods:>11.2f}{per:>11.0f}')
    print(f'  {"total":<58}{"":>11}{total:>11.0f}')
    return total


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--run', default='pinv', help=f'the run of {SCENARIO} (default pinv)')
    args = parser.parse_args()
    callbacks, publishes = instrument()
    start = time.perf_counter()
    logs, _ = run_experiment(load_scenario(SCENARIO), runs=[args.run], engine='nodes', show_progress=False)
    wall = time.perf_counter() - start
    periods = len(logs[args.run])
    print(
        f'\n{SCENARIO} {args.run}, nodes engine: {periods} periods, {wall:.1f} s wall, '
        f'{wall / periods * 1e3:.2f} ms a period ({periods * 0.025 / wall:.1f}x real time)'
    )
    in_callbacks = report('callbacks (the node\'s work, publishes included)', callbacks, periods)
    in_publish = report('publishes', publishes, periods)
    print(
        f'  the rest (executor, middleware, messages to Python): {wall / periods * 1e6 - in_callbacks:.0f} µs a period; '
        f'publishes are {in_publish:.0f} µs of the callbacks'
    )


if __name__ == '__main__':
    main()
