"""Any robot the package loads: wmm_sim, the base controller of its base family
(swmr_controller, mecanum_controller or differential_controller), redundancy_resolver and, with
planner:=true, goal_planner between /goal_pose and the resolver.

    ros2 launch wmm_control robot.launch.py robot:=<name or robot YAML path> [use_sim_time:=true] [viewer:=true]
        [obstacles:=<name in config/obstacles or YAML path>] [planner:=true]
"""

from wmm_control.launching import robot_launch_description


def generate_launch_description():
    return robot_launch_description()
