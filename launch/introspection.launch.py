"""The introspection nodes with their parameter files; one or two arms as a launch argument.

ros2 launch rcbht_introspection introspection.launch.py arms:=two model_file:=$HOME/model.rcbht
verifier_node (failure detection, /task_health) runs with verifier:=true or a verifier_file;
closed_loop:=true adds sim_node (the simulated cell) and planner_node (policy:=...).
"""

from __future__ import annotations

import os
import re
from typing import Any

from ament_index_python.packages import get_package_share_directory
from launch import LaunchContext, LaunchDescription
from launch.actions import DeclareLaunchArgument, OpaqueFunction
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node

PACKAGE = "rcbht_introspection"
ARM_SETS = {"one": ["R"], "two": ["L", "R"]}


def parse_arms(value: str) -> list[str]:
    """Arm names from 'one', 'two' or a list such as '[L, R]'; '' keeps the files' arms."""
    value = value.strip()
    if not value or value in ARM_SETS:
        return list(ARM_SETS.get(value, []))
    arms = [arm for arm in re.split(r"[\s,'\"]+", value[1:-1]) if arm]
    if not (value[0] + value[-1] == "[]" and 0 < len(arms) == len(set(arms)) <= 2):
        raise ValueError(f"arms: expected one, two or a list such as [L, R], got {value!r}")
    return arms


def arm_parameters(arms: list[str]) -> tuple[dict[str, Any], dict[str, Any]]:
    """Segmenter and classifier parameters for `arms` (no arms: the files' values stand)."""
    if not arms:
        return {}, {}
    topics = ["/wrench"] if len(arms) == 1 else [f"/{arm}/wrench" for arm in arms]
    return {"arms": arms, "wrench_topics": topics}, {"arms": arms}


def verifier_enabled(value: str, verifier_file: str) -> bool:
    """The `verifier` launch argument: true or false ('' : on when a verifier_file is given)."""
    value = value.strip().lower()
    if value not in ("", "true", "false"):
        raise ValueError(f"verifier: expected true or false, got {value!r}")
    return value == "true" or (value == "" and bool(verifier_file))


def switch(name: str, value: str) -> bool:
    """A true/false launch argument ('' is false)."""
    value = value.strip().lower()
    if value not in ("", "true", "false"):
        raise ValueError(f"{name}: expected true or false, got {value!r}")
    return value == "true"


def launch_nodes(context: LaunchContext) -> list[Node]:
    """The nodes, their parameters computed from the launch arguments."""
    segmenter, classifier = arm_parameters(parse_arms(LaunchConfiguration("arms").perform(context)))
    verifier = dict(segmenter)
    model_file = LaunchConfiguration("model_file").perform(context)
    if model_file:
        classifier["model_file"] = os.path.abspath(os.path.expanduser(model_file))
        if os.path.isfile(classifier["model_file"]):  # a teaching cold start has none yet
            segmenter["taxonomy_model_file"] = classifier["model_file"]  # the model's profile
    # Plain Node actions: the nodes are lifecycle nodes whose `autostart` parameter (default
    # true) takes them to active by themselves; set autostart: false to drive the transitions.
    verifier_file = LaunchConfiguration("verifier_file").perform(context)
    if verifier_file:
        verifier["verifier_file"] = os.path.abspath(os.path.expanduser(verifier_file))
    chosen = [("segmenter_node", segmenter), ("classifier_node", classifier)]
    closed_loop = switch("closed_loop", LaunchConfiguration("closed_loop").perform(context))
    if closed_loop or verifier_enabled(
        LaunchConfiguration("verifier").perform(context), verifier_file
    ):
        chosen.append(("verifier_node", verifier))
    if closed_loop:
        planner = {"policy": LaunchConfiguration("policy").perform(context)}
        if verifier_file:
            planner["verifier_file"] = verifier["verifier_file"]
        chosen += [("sim_node", {}), ("planner_node", planner)]
    nodes = []
    for name, overrides in chosen:
        params_file = LaunchConfiguration(name.replace("_node", "_params")).perform(context)
        parameters = [params_file, overrides] if overrides else [params_file]
        nodes.append(
            Node(
                package=PACKAGE, executable=name, name=name, output="screen", parameters=parameters
            )
        )
    return nodes


def generate_launch_description() -> LaunchDescription:
    """Launch arguments arms, model_file, verifier, verifier_file and the parameter files."""
    config = os.path.join(get_package_share_directory(PACKAGE), "config")
    return LaunchDescription(
        [
            DeclareLaunchArgument(
                "arms",
                default_value="",
                description="one ([R]), two ([L, R]: /L/wrench, /R/wrench) or a list such as "
                "[L, R]; empty: as in the parameter files",
            ),
            DeclareLaunchArgument(
                "model_file",
                default_value="",
                description="model file written by `rcbht train` (empty: as in classifier_params); "
                "an existing one is also the segmenter's taxonomy_model_file",
            ),
            DeclareLaunchArgument(
                "verifier",
                default_value="",
                description="true: run verifier_node too (failure detection, /task_health); "
                "empty: only when verifier_file is given",
            ),
            DeclareLaunchArgument(
                "verifier_file",
                default_value="",
                description="verifier file written by `rcbht verify-train` (empty: as in "
                "verifier_params)",
            ),
            DeclareLaunchArgument(
                "closed_loop",
                default_value="false",
                description="true: also sim_node (the simulated snap cell) and planner_node",
            ),
            DeclareLaunchArgument(
                "policy",
                default_value="introspect",
                description="planner_node's policy: none, retry, search, introspect or oracle",
            ),
            DeclareLaunchArgument(
                "segmenter_params",
                default_value=os.path.join(config, "segmenter.yaml"),
                description="segmenter_node ROS parameter file",
            ),
            DeclareLaunchArgument(
                "classifier_params",
                default_value=os.path.join(config, "classifier.yaml"),
                description="classifier_node ROS parameter file",
            ),
            DeclareLaunchArgument(
                "verifier_params",
                default_value=os.path.join(config, "verifier.yaml"),
                description="verifier_node ROS parameter file",
            ),
            DeclareLaunchArgument(
                "sim_params",
                default_value=os.path.join(config, "sim_node.yaml"),
                description="sim_node ROS parameter file",
            ),
            DeclareLaunchArgument(
                "planner_params",
                default_value=os.path.join(config, "planner.yaml"),
                description="planner_node ROS parameter file",
            ),
            OpaqueFunction(function=launch_nodes),
        ]
    )
