"""Architecture rules: cores never import ROS; the ego side never subscribes to ground truth."""

from __future__ import annotations

import re
from pathlib import Path

SRC = Path(__file__).resolve().parents[1] / "src"
CORE_FILES = [*SRC.glob("avp_world/avp_world/**/*.py"), *SRC.glob("avp_sim/avp_sim/core/*.py"),
              *SRC.glob("avp_planner/avp_planner/core/*.py"), *SRC.glob("avp_perception/avp_perception/core/*.py"),
              SRC / "avp_planner/avp_planner/scripted_driver.py",
              *[f for f in SRC.glob("avp_bringup/avp_bringup/experiment/*.py") if f.name != "ros_transport.py"]]
ROS_IMPORT = re.compile(r"^\s*(import|from)\s+(rclpy|avp_msgs|geometry_msgs|std_msgs|nav_msgs|sensor_msgs|"
                        r"visualization_msgs|rosgraph_msgs|builtin_interfaces)\b", re.M)


def test_cores_are_ros_free():
    assert len(CORE_FILES) >= 20
    offenders = [str(f) for f in CORE_FILES if ROS_IMPORT.search(f.read_text())]
    assert offenders == []


def test_ego_nodes_never_touch_ground_truth():
    ego_side = [*SRC.glob("avp_planner/avp_planner/*.py"), *SRC.glob("avp_perception/avp_perception/**/*.py"),
                SRC / "avp_bringup/avp_bringup/experiment/ego.py"]
    assert ego_side
    for f in ego_side:
        text = f.read_text()
        assert "ground_truth" not in text and "GroundTruth" not in text, f


def test_runtime_packages_never_import_training():
    """Training (data generation, fitting, evaluation) lives in avp_training; the runtime packages only run the
    shipped models. Only the `avp` command line reaches it, for `avp train-intent|gen-intent-data|train-trajectory`."""
    allowed = {SRC / "avp_bringup/avp_bringup/cli.py"}
    runtime = ("avp_world", "avp_common", "avp_sim", "avp_perception", "avp_planner", "avp_bringup")
    offenders = [str(f) for pkg in runtime for f in SRC.glob(f"{pkg}/{pkg}/**/*.py")
                 if f not in allowed and re.search(r"^\s*(from|import)\s+avp_training\b", f.read_text(), re.M)]
    assert offenders == []
    assert not (SRC / "avp_perception/avp_perception/training").exists()
    assert "<exec_depend>avp_training</exec_depend>" in (SRC / "avp_bringup/package.xml").read_text()
