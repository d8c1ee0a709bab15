"""Two robots in one domain, in namespaces /r1 (robot1:=, default steerable) and /r2 (robot2:=,
default mecanum); each robot's nodes follow its own simulator's clock (/r1/clock, /r2/clock);
viewer:=true shows /r1.

    ros2 launch wmm_control two_robots.launch.py [robot1:=...] [robot2:=...] [use_sim_time:=true] [viewer:=true]
"""

from wmm_control.launching import two_robots_launch_description


def generate_launch_description():
    return two_robots_launch_description()
