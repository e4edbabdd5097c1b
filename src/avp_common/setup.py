from glob import glob

from setuptools import find_packages, setup

package_name = "avp_common"

setup(
    name=package_name,
    version="0.17.0",
    packages=find_packages(exclude=["test"]),
    package_data={package_name: ["maps/*.yaml", "models/*"]},
    data_files=[
        ("share/ament_index/resource_index/packages", ["resource/" + package_name]),
        ("share/" + package_name, ["package.xml"]),
        ("share/" + package_name + "/config", glob("config/*.yaml")),
        ("share/" + package_name + "/launch", glob("launch/*.launch.py")),
    ],
    install_requires=["setuptools"],
    zip_safe=True,
    maintainer="AVP stack maintainers",
    maintainer_email="maintainers@avp-stack.org",
    description="ROS glue shared by the AVP nodes: message conversions, QoS profiles, validated parameters.",
    license="Apache-2.0",
    entry_points={"console_scripts": ["component_container = avp_common.container:main"]},
)
