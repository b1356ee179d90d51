"""ament_python package hasel_driver: thin rclpy nodes over the ROS-free core library ``hasel``."""
from setuptools import setup

package_name = "hasel_driver"

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
            "strain_driver = hasel_driver.driver_node:main",
            "lowpass_filter = hasel_driver.filter_node:main",
            "serial_bridge = hasel_driver.serial_node:main",
        ],
    },
)
