import os
from glob import glob

from setuptools import find_packages, setup

package_name = "gait_estimator"


def data_tree(top: str) -> list[tuple[str, list[str]]]:
    """(share/gait_estimator/<dir>, [files]) for every directory below ``top`` (bundled data)."""
    return [
        (os.path.join("share", package_name, root), [os.path.join(root, f) for f in sorted(files)])
        for root, _, files in sorted(os.walk(top))
        if files
    ]


ROS = ["ros-jazzy-rclpy", "ros-jazzy-common-interfaces", "ros-jazzy-rmw-fastrtps-cpp"]
EXTRAS = {
    "fast": ["numba>=0.59"],  # the compiled matcher step; without it the pure-numpy step runs (slower)
    "analysis": ["scipy>=1.11", "matplotlib>=3.6"],  # train, evaluate, label tools, figures
    "bags": ["rosbags>=0.10"],  # rosbag2 (mcap, sqlite3) reading and writing without ROS
    "ros": [*ROS, "rosbags>=0.10"],  # estimator_node, demo, play; numba recommended: [ros,fast]
    # + Debian's chromium(-driver); imufusion: the reference the raw-IMU fusion is tested against
    "test": ["pytest>=7", "hypothesis>=6.80", "ruff>=0.5", "wheel", "selenium>=4.20", "imufusion>=1.3.3"],
    "colcon": ["colcon-common-extensions", "ros-jazzy-ament-package"],
    "imu": ["numba>=0.59"],  # raw IMUs' fusion compiled (without: plain Python, slower; docs/imu.md)
    "dashboard": ["aiohttp>=3.9"],  # gait-estimator dashboard (with [ros]); the page's chart library is bundled
}
EXTRAS["all"] = sorted({r for reqs in EXTRAS.values() for r in reqs})


setup(
    name=package_name,
    version="0.1.0",
    description="Locomotion mode and gait phase estimation by kernel matching (ROS 2 node and offline tools)",
    long_description=open("README.md", encoding="utf-8").read(),
    long_description_content_type="text/markdown",
    license="MIT",
    python_requires=">=3.10",
    packages=find_packages(exclude=["test", "test.*"]),
    package_data={"gait_estimator.dashboard": ["static/*.*", "static/vendor/uplot/*"]},
    data_files=[
        ("share/ament_index/resource_index/packages", ["resource/" + package_name]),
        ("share/" + package_name, ["package.xml"]),
        ("share/" + package_name + "/config", glob("config/*.yaml")),
        ("share/" + package_name + "/config/kernels", glob("config/kernels/*.yaml")),
        ("share/" + package_name + "/launch", glob("launch/*.launch.xml")),
        *data_tree("data"),
    ],
    # The estimator, the offline `process` and the file formats need numpy and PyYAML only; the
    # rest is optional (a missing extra is reported in one line naming it).
    install_requires=[
        "numpy>=1.26",
        "pyyaml>=6.0",
    ],
    extras_require=EXTRAS,
    zip_safe=False,
    entry_points={
        "console_scripts": [
            "gait-estimator = gait_estimator.cli:main",
            "estimator_node = gait_estimator.ros:node_main",
            "estimator_dashboard = gait_estimator.cli.dashboard_command:main",
        ],
    },
)
