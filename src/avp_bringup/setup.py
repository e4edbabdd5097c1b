from glob import glob

from setuptools import find_packages, setup

package_name = "avp_bringup"

setup(
    name=package_name,
    version="0.17.0",
    packages=find_packages(exclude=["test"]),
    package_data={package_name: ["dds/*.xml"]},
    data_files=[
        ("share/ament_index/resource_index/packages", ["resource/" + package_name]),
        ("share/" + package_name, ["package.xml", "README.md"]),
        ("share/" + package_name + "/launch", glob("launch/*.launch.py")),
    ],
    install_requires=["setuptools"],
    zip_safe=True,
    maintainer="AVP stack maintainers",
    maintainer_email="maintainers@avp-stack.org",
    description="The avp command, the node graph's launcher and launch file, the lifecycle client, the demo.",
    license="Apache-2.0",
    entry_points={"console_scripts": []},
)
