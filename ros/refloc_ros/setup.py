from glob import glob

from setuptools import setup

package_name = "refloc_ros"

setup(
    name=package_name,
    version="0.1.0",
    packages=[package_name],
    data_files=[
        ("share/ament_index/resource_index/packages", ["resource/" + package_name]),
        ("share/" + package_name, ["package.xml", "README.md"]),
        ("share/" + package_name + "/launch", glob("launch/*.launch.py")),
    ],
    install_requires=["setuptools"],
    zip_safe=True,
    maintainer="refloc",
    maintainer_email="refloc@example.invalid",
    description="Global localization from one laser scan (refloc) for ROS 2",
    license="MIT OR Apache-2.0",
    tests_require=["pytest"],
    entry_points={"console_scripts": ["refloc_node = refloc_ros.node:main"]},
)
