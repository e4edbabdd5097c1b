"""ros2 launch avp_bringup avp.launch.py [params_file:=FILE] — for full ROS 2 Jazzy installs.

On machines with ROS 2 from PyPI (no `launch` package) use `avp launch`, which starts the same
nodes with the same parameter files (avp_bringup/graph.py).
"""

import os

from ament_index_python.packages import get_package_share_directory
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument
from launch.conditions import IfCondition
from launch.substitutions import LaunchConfiguration, PythonExpression
from launch_ros.actions import Node


def generate_launch_description() -> LaunchDescription:
    sim_params = os.path.join(get_package_share_directory("avp_sim"), "config", "sim.param.yaml")
    drv_params = os.path.join(get_package_share_directory("avp_planner"), "config", "scripted_driver.param.yaml")
    user = LaunchConfiguration("params_file")
    has_user = PythonExpression(["'", user, "' != ''"])
    return LaunchDescription([
        DeclareLaunchArgument("params_file", default_value="", description="extra parameter file"),
        Node(package="avp_sim", executable="sim_node", name="avp_sim", namespace="avp",
             parameters=[sim_params], output="screen", condition=IfCondition(PythonExpression(["not ", has_user]))),
        Node(package="avp_sim", executable="sim_node", name="avp_sim", namespace="avp",
             parameters=[sim_params, user], output="screen", condition=IfCondition(has_user)),
        Node(package="avp_planner", executable="scripted_driver", name="scripted_driver", namespace="avp",
             parameters=[drv_params], output="screen"),
    ])
