"""Robot A ('steerable'): wmm_sim, its base controller and redundancy_resolver (viewer:=true adds wmm_viewer).

ros2 launch wmm_control robot_a.launch.py [use_sim_time:=true] [viewer:=true]
"""

from wmm_control.launching import robot_launch_description


def generate_launch_description():
    return robot_launch_description('steerable')
