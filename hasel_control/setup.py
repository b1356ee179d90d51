"""ament_python package hasel_control: thin rclpy nodes over the ROS-free core library ``hasel``."""
from setuptools import setup

package_name = "hasel_control"

setup(
    name=package_name,
    version="0.1.0",
    packages=[package_name],
    data_files=[
        ("share/ament_index/resource_index/packages", ["resource/" + package_name]),
        ("share/" + package_name, ["package.xml"]),
        ("share/" + package_name + "/config", ["config/loop.yaml"]),
    ],
    install_requires=["setuptools"],
    zip_safe=True,
    maintainer="HASEL toolkit developers",
    maintainer_email="hasel-toolkit@example.com",
    description="See package.xml",
    license="Apache-2.0",
    entry_points={
        "console_scripts": [
            "pid_controller = hasel_control.controller_node:main",
            "hv_amplifier = hasel_control.amplifier_node:main",
            "reference_generator = hasel_control.reference_node:main",
        ],
    },
)
