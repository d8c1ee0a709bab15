"""The QoS profiles of the nodes' topics, one per kind of topic (docs/nodes.md's table)."""

from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

__all__ = ['STATE_PUB_QOS', 'STATE_SUB_QOS', 'COMMAND_QOS', 'CLOCK_QOS', 'DIAGNOSTICS_QOS', 'LATCHED_QOS']


#: State streams a node *publishes* (``joint_states``, ``odom``, ``ee_pose``): reliable, keep
#: last 10, volatile (the system default), so that reliable and best-effort subscribers both
#: match (REP 2003: a sensor source publishes reliable, its consumers choose).
STATE_PUB_QOS = QoSProfile(
    history=HistoryPolicy.KEEP_LAST,
    depth=10,
    reliability=ReliabilityPolicy.RELIABLE,
    durability=DurabilityPolicy.VOLATILE,
)
#: State streams a node *consumes*: best effort, keep last 1, volatile. A late sample is worth
#: less than the next one, and never stalls the sender; only the newest is kept, so a node that
#: was held up (a stall, a busy machine) answers the state of now, not a backlog of states the
#: simulator has already stepped past (their answers would be applied late, one by one).
STATE_SUB_QOS = QoSProfile(
    history=HistoryPolicy.KEEP_LAST,
    depth=1,
    reliability=ReliabilityPolicy.BEST_EFFORT,
    durability=DurabilityPolicy.VOLATILE,
)
#: Commands and set-points (``*/commands``, ``base/reference``, ``base/feasible_twist``,
#: ``goal_pose``, ``ee_reference``): reliable, keep last 10, volatile: none is lost (the base
#: exchange matches each reference to its joint state by stamp, so two queued references must
#: both arrive), and none is replayed to a late joiner.
COMMAND_QOS = QoSProfile(
    history=HistoryPolicy.KEEP_LAST,
    depth=10,
    reliability=ReliabilityPolicy.RELIABLE,
    durability=DurabilityPolicy.VOLATILE,
)
#: ``/clock``: reliable, keep last 1 (only the newest time matters; rclpy's time source
#: subscribes best effort, which matches).
CLOCK_QOS = QoSProfile(
    history=HistoryPolicy.KEEP_LAST,
    depth=1,
    reliability=ReliabilityPolicy.RELIABLE,
    durability=DurabilityPolicy.VOLATILE,
)
#: ``/diagnostics``: reliable, keep last 10, volatile (what diagnostic_aggregator expects).
DIAGNOSTICS_QOS = STATE_PUB_QOS
#: What a node states once and a late subscriber must still get (``robot_description``,
#: ``/tf_static``, ``base/lag``): reliable, transient local, keep last 1 (what
#: robot_state_publisher and tf2's static broadcaster offer).
LATCHED_QOS = QoSProfile(
    history=HistoryPolicy.KEEP_LAST,
    depth=1,
    reliability=ReliabilityPolicy.RELIABLE,
    durability=DurabilityPolicy.TRANSIENT_LOCAL,
)
