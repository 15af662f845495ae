"""ament_python package set-up: works under colcon (ROS install) and plain pip (PyPI wheels)."""

from glob import glob

from setuptools import find_packages, setup

package_name = "rcbht_introspection"

setup(
    name=package_name,
    version="0.1.0",
    packages=find_packages(exclude=["test", "test.*"]),
    data_files=[
        ("share/ament_index/resource_index/packages", [f"resource/{package_name}"]),
        (f"share/{package_name}", ["package.xml"]),
        (f"share/{package_name}/config", glob("config/*.yaml") + glob("config/*.xml")),
        # the simulator's experiment configurations, apart from the nodes' configuration
        (f"share/{package_name}/config/sim", glob("config/sim/*.yaml")),
        (f"share/{package_name}/config/recovery", glob("config/recovery/*.yaml")),
        (f"share/{package_name}/launch", glob("launch/*.launch.py")),
        # `ros2 run rcbht_introspection <node>` looks for lib/<package>/<executable>; data_files
        # put them there under colcon and under plain pip alike (console_scripts go to bin/ with pip)
        (f"lib/{package_name}", ["scripts/segmenter_node", "scripts/classifier_node", "scripts/verifier_node", "scripts/sim_node", "scripts/planner_node"]),
    ],
    # the runtime (nodes, core, bag tools, CLI) beside rclpy and the messages, at the pins of
    # requirements*.txt (a test keeps them equal)
    install_requires=[
        "numpy==2.3.5",
        "scipy==1.17.1",
        "scikit-learn==1.9.1",
        "PyYAML==6.0.3",
        "rosbags==0.11.9",
        "skops==0.16.0",
        "joblib==1.6.0",
        "aeon==1.6.0",  # MiniRocket: the verifier's shape head
    ],
    # optional tools around the core, all installed by `make setup`: the MuJoCo simulator, the
    # plots, terminal progress bars, the anchors' peer baselines (requirements-peers.txt) and
    # verify-eval --scheduler on a dask.distributed cluster
    extras_require={
        "sim": ["mujoco==4.0.0", "tqdm==4.70.1"],
        "plots": ["matplotlib==3.11.2"],
        "progress": ["tqdm==4.70.1"],
        "peers": ["hmmlearn==0.3.3"],
        "fleet": ["dask==2026.8.0", "distributed==2026.8.0"],
    },
    python_requires=">=3.11",
    zip_safe=True,
    maintainer="rcbht_introspection maintainers",
    maintainer_email="rcbht@example.org",
    description="RCBHT wrench action grammar and sub-task introspection for ROS 2 Jazzy",
    license="Apache-2.0",
    entry_points={
        "console_scripts": [
            "rcbht = rcbht_introspection.cli:main",
        ],
    },
)
