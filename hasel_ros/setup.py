"""ament_python package hasel_ros: the ROS plumbing shared by the toolkit's packages."""
from setuptools import setup

package_name = "hasel_ros"

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
)
