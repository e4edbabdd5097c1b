from glob import glob

from setuptools import find_packages, setup

package_name = "avp_episode"

setup(
    name=package_name,
    version="0.17.0",
    packages=find_packages(exclude=["test"]),
    data_files=[
        ("share/ament_index/resource_index/packages", ["resource/" + package_name]),
        ("share/" + package_name, ["package.xml"]),
        ("share/" + package_name + "/config/methods", glob("config/methods/*.yaml")),
        ("share/" + package_name + "/config/protocols", glob("config/protocols/*.yaml")),
    ],
    install_requires=["setuptools"],
    zip_safe=True,
    maintainer="AVP stack maintainers",
    maintainer_email="maintainers@avp-stack.org",
    description="ROS-free episode of the experiment.",
    license="Apache-2.0",
    entry_points={"console_scripts": []},
)
