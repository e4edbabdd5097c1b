"""ros2 launch avp_bringup avp.launch.py [params_file:=FILE] — for full ROS 2 Jazzy installs.

Starts the graph of ``avp launch`` (avp_bringup/graph.py ``default_graph("planner")``): the simulator, the
belief node, the prediction node and the planner (waiting for beliefs and predictions), each with its
package's parameter file, then ``params_file`` when given. On machines with ROS 2 from PyPI (no `launch`
package) use `avp launch`, which starts the same nodes with the same parameter files.
"""

import os

from ament_index_python.packages import get_package_share_directory
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument
from launch.conditions import IfCondition
from launch.substitutions import LaunchConfiguration, PythonExpression
from launch_ros.actions import Node

# (package, executable, node name, parameter file, parameters set by the graph) as in graph.default_graph
NODES = [
    ("avp_sim", "sim_node", "avp_sim", "sim.param.yaml", {"min_subscribers": 3}),
    ("avp_perception", "belief_node", "avp_belief", "belief.param.yaml", {}),
    ("avp_perception", "prediction_node", "avp_prediction", "prediction.param.yaml", {}),
    ("avp_planner", "planner", "avp_planner", "planner.param.yaml", {"use_beliefs": True, "use_predictions": True}),
]


def generate_launch_description() -> LaunchDescription:
    user = LaunchConfiguration("params_file")
    has_user = PythonExpression(["'", user, "' != ''"])
    actions = [DeclareLaunchArgument("params_file", default_value="", description="extra parameter file")]
    for pkg, exe, name, yaml_file, extra in NODES:
        params = os.path.join(get_package_share_directory(pkg), "config", yaml_file)
        actions.append(Node(package=pkg, executable=exe, name=name, namespace="avp", output="screen",
                            parameters=[params, extra], condition=IfCondition(PythonExpression(["not ", has_user]))))
        actions.append(Node(package=pkg, executable=exe, name=name, namespace="avp", output="screen",
                            parameters=[params, user, extra], condition=IfCondition(has_user)))
    return LaunchDescription(actions)
