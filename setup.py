"""ament_python package setup: works with ``colcon build`` and with plain ``pip install -e .``."""

from glob import glob

from setuptools import find_packages, setup

PACKAGE = "dualarm_control"

# The one place where dependency versions are pinned (ranges).
INSTALL_REQUIRES = [
    "numpy>=1.26,<3",
    "scipy>=1.11,<2",
    "PyYAML>=6,<7",
    "pin>=3.1,<5",
    "daqp>=0.11,<0.12",  # default QP back-end (exact dual active-set); needs primal_start/eta_prox
    "proxsuite>=0.6,<0.9",
    "pybullet>=3.2.6,<3.3",
    "ruckig>=0.12,<0.20",
    "qpsolvers>=4.3,<5",
    "quadprog>=0.1.11,<0.2",
    "matplotlib>=3.8,<4",
    "rosbags>=0.10,<0.12",
    "tqdm>=4.66,<5",  # progress bars of long runs (rate, time left)
]
# ROS 2 Jazzy from PyPI (rclpy, the message packages of the graph, Jazzy's default RMW).
# An extra, so that on a machine with ROS 2 from apt (colcon workspace, sourced setup) the
# system rclpy is used and nothing from PyPI shadows it: there, install without "[ros]".
ROS_REQUIRES = [
    "ros-jazzy-rclpy>=7.1,<8",
    "ros-jazzy-common-interfaces>=5.3,<6",
    "ros-jazzy-rmw-fastrtps-cpp>=8.4,<9",
    "ros-jazzy-ament-index-python>=1.8,<2",
]
TEST_REQUIRES = ["pytest>=8,<10", "hypothesis>=6.100,<7", "ruff>=0.5", "mypy>=1.10",
                 "pytest-xdist>=3.5,<4", "pytest-timeout>=2.3,<3", "psutil>=5.9",  # docs/testing.md
                 "colcon-common-extensions>=0.3,<1",
                 "websocket-client>=1.7,<2"]  # the browser test drives headless Chromium (DevTools protocol)
# `dualarm bench` compares with pink's solve_ik; not needed by the controller itself.
BENCH_REQUIRES = ["pin-pink>=4.4,<5"]
# Seeing the cell: `dualarm view` (the Rerun viewer, whose web viewer ships in the wheel and runs
# offline; video via imageio-ffmpeg, whose ffmpeg ships in the wheel; the Foxglove WebSocket server
# via foxglove-sdk).
# Robots beyond the LWR4 cell (config/robots/baxter.yaml, panda_pair, ur5_pair): their URDFs and meshes.
ROBOTS_REQUIRES = ["example-robot-data>=6,<7"]
# `dualarm sweep` (issue 28): closed-loop runs as Dask tasks, rows in Parquet, tqdm progress.
SWEEP_REQUIRES = ["dask>=2024.8,<2028", "distributed>=2024.8,<2028", "pyarrow>=15,<28", "tqdm>=4.66,<5"]
VIEW_REQUIRES = ["rerun-sdk>=0.41,<0.42", "imageio-ffmpeg>=0.5,<0.9", "foxglove-sdk>=0.30,<0.31"]

setup(
    name=PACKAGE,
    version="0.1.0",
    packages=find_packages(include=["dualarm_control", "dualarm_control.*", "dualarm_sim", "dualarm_sim.*"]),
    data_files=[
        ("share/ament_index/resource_index/packages", [f"resource/{PACKAGE}"]),
        (f"share/{PACKAGE}", ["package.xml"]),
        (f"share/{PACKAGE}/config", glob("config/*.yaml") + glob("config/*.xml")),
        (f"share/{PACKAGE}/config/solvers", glob("config/solvers/*.yaml")),
        (f"share/{PACKAGE}/config/scenarios", glob("config/scenarios/*.yaml")),
        (f"share/{PACKAGE}/config/robots", glob("config/robots/*.yaml")),
        (f"share/{PACKAGE}/config/sweeps", glob("config/sweeps/*.yaml")),
        (f"share/{PACKAGE}/config/hardware", glob("config/hardware/*.yaml")),
        (f"share/{PACKAGE}/config/tools", glob("config/tools/*.yaml")),
        (f"share/{PACKAGE}/urdf", glob("urdf/*.urdf")),
        (f"share/{PACKAGE}/launch", glob("launch/*.launch.py")),
    ],
    install_requires=INSTALL_REQUIRES,
    extras_require={"ros": ROS_REQUIRES, "test": TEST_REQUIRES, "bench": BENCH_REQUIRES,
                    "view": VIEW_REQUIRES, "robots": ROBOTS_REQUIRES,
                    "sweep": SWEEP_REQUIRES},
    python_requires=">=3.10",
    zip_safe=True,
    maintainer="dualarm_control developers",
    maintainer_email="dev@dualarm-control.invalid",
    description="Sparse hierarchical QP relative-pose control of a simulated dual-arm cell.",
    license="Apache-2.0",
    entry_points={
        "console_scripts": [
            "dualarm = dualarm_control.app.cli:main",
            "controller_node = dualarm_control.nodes.controller_node:main",
            "trajectory_node = dualarm_control.nodes.trajectory_node:main",
            "sim_node = dualarm_sim.sim_node:main",
            "cell_container = dualarm_control.nodes.container:main",
        ],
    },
)
