from glob import glob

from setuptools import find_packages, setup

package_name = "avp_tracking"

setup(
    name=package_name,
    version="0.17.0",
    packages=find_packages(exclude=["test"]),
    data_files=[
        ("share/ament_index/resource_index/packages", ["resource/" + package_name]),
        ("share/" + package_name, ["package.xml"]),
        ("share/" + package_name + "/config", glob("config/*.yaml")),
    ],
    install_requires=["setuptools"],
    zip_safe=True,
    maintainer="AVP stack maintainers",
    maintainer_email="maintainers@avp-stack.org",
    description="Multi-object tracker between the sensing model (or a real detector) and the ego's perception.",
    license="Apache-2.0",
    entry_points={"console_scripts": [
        "tracker_node = avp_tracking.tracker_node:main",
    ]},
)
