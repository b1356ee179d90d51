"""ament_python package hasel_sysid: thin rclpy nodes over the ROS-free core library ``hasel``."""
from setuptools import setup

package_name = "hasel_sysid"

setup(
    name=package_name,
    version="0.1.0",
    packages=[package_name],
    data_files=[
        ("share/ament_index/resource_index/packages", ["resource/" + package_name]),
        ("share/" + package_name, ["package.xml"]),
    ],
    install_requires=["setuptools"],
    zip_safe=True,
    maintainer="HASEL toolkit developers",
    maintainer_email="hasel-toolkit@example.com",
    description="See package.xml",
    license="Apache-2.0",
    entry_points={
        "console_scripts": [
            "recorder = hasel_sysid.recorder_node:main",
        ],
        # subcommands of `hasel` (the core finds them here; see hasel.cli)
        "hasel.commands": [
            f"{name} = hasel_sysid.commands:{name.upper()}"
            for name in ("steps", "compare", "calibrate", "chirp", "record", "replay", "demo")
        ],
    },
)
