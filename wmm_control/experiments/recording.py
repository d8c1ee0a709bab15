"""A rosbag2 (MCAP) recording of every topic of an experiment run, written with ``rosbags``.

:class:`BagRecorder` is one more node of the run: it subscribes, as serialized messages (no
deserialisation: the bytes go to the file as they came), to every topic the run's nodes
publish, with each publisher's reliability and durability, and writes them to a rosbag2
folder (``metadata.yaml`` and one ``.mcap`` file) that ``ros2 bag info`` and ``ros2 bag play``
open. A message's log time is the recorder's ROS clock at receipt, on the simulator's time
(``use_sim_time``; as ``ros2 bag record --use-sim-time``). The message definitions come from
rosbags' ROS 2 Jazzy type store; a topic whose type it lacks is left out and named in
:attr:`BagRecorder.skipped`.
"""

from __future__ import annotations

from functools import partial
from pathlib import Path

from rclpy.context import Context
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import QoSProfile
from rosbags.interfaces import Connection
from rosbags.rosbag2 import StoragePlugin, Writer
from rosbags.typesys import Stores, get_typestore

from wmm_control.errors import ConfigError

__all__ = ['BagRecorder']


def _type_class(type_name: str):
    """The rclpy message class of ``pkg/msg/Name``."""
    package, _kind, name = type_name.split('/')
    module = __import__(f'{package}.msg', fromlist=[name])
    return getattr(module, name)


class BagRecorder(Node):
    """Records every topic of its context's graph to the rosbag2 folder ``path`` (MCAP).

    Call :meth:`subscribe_all` once the run's nodes exist (their publishers are then in the
    graph), and :meth:`close` at the end (it writes ``metadata.yaml``).

    Args:
        context: the run's rclpy context.
        path: the rosbag2 folder to create (it must not exist).

    Raises:
        ConfigError: ``path`` exists already.
    """

    def __init__(self, context: Context, path: str | Path) -> None:
        super().__init__('experiment_bag', context=context, parameter_overrides=[Parameter('use_sim_time', value=True)])
        self.path = Path(path)
        if self.path.exists():
            raise ConfigError(f'recording {self.path}: it exists already')
        self._typestore = get_typestore(Stores.ROS2_JAZZY)
        self._writer: Writer | None = Writer(self.path, version=9, storage_plugin=StoragePlugin.MCAP)
        self._writer.open()
        self._connections: dict[str, Connection] = {}
        #: Messages written, by topic.
        self.counts: dict[str, int] = {}
        #: Topics left out, with the reason.
        self.skipped: dict[str, str] = {}

    def subscribe_all(self) -> list[str]:
        """Subscribe to every topic published in the graph that is not yet recorded; the topics added."""
        added = []
        for topic, types in self.get_topic_names_and_types():
            if topic in self._connections or topic in self.skipped:
                continue
            publishers = [i for i in self.get_publishers_info_by_topic(topic) if i.node_name != self.get_name()]
            if not publishers:
                continue
            type_name = types[0]
            if type_name not in self._typestore.types:
                self.skipped[topic] = f'type {type_name} is not in rosbags\' ROS 2 Jazzy type store'
                continue
            offered = publishers[0].qos_profile
            qos = QoSProfile(depth=100, reliability=offered.reliability, durability=offered.durability)
            assert self._writer is not None, 'subscribe_all() after close()'
            self._connections[topic] = self._writer.add_connection(topic, type_name, typestore=self._typestore)
            self.counts[topic] = 0
            self.create_subscription(_type_class(type_name), topic, partial(self._write, topic), qos, raw=True)
            added.append(topic)
        return added

    def _write(self, topic: str, data: bytes) -> None:
        assert self._writer is not None, 'a message after close()'
        self._writer.write(self._connections[topic], self.get_clock().now().nanoseconds, data)
        self.counts[topic] += 1

    def close(self) -> None:
        """Finish the file and write ``metadata.yaml`` (once)."""
        if self._writer is not None:
            self._writer.close()
            self._writer = None

    def destroy_node(self) -> None:
        self.close()
        super().destroy_node()
