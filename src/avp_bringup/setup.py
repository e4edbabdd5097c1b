from glob import glob

from setuptools import find_packages, setup

package_name = "avp_bringup"

setup(
    name=package_name,
    version="0.1.0",
    packages=find_packages(exclude=["test"]),
    package_data={package_name: ["dds/*.xml", "experiment/*.csv"]},
    data_files=[
        ("share/ament_index/resource_index/packages", ["resource/" + package_name]),
        ("share/" + package_name, ["package.xml"]),
        ("share/" + package_name + "/config", glob("config/*.yaml")),
        ("share/" + package_name + "/config/methods", glob("config/methods/*.yaml")),
        ("share/" + package_name + "/config/protocols", glob("config/protocols/*.yaml")),
        ("share/" + package_name + "/launch", glob("launch/*.launch.py")),
    ],
    install_requires=["setuptools"],
    zip_safe=True,
    maintainer="AVP stack maintainers",
    maintainer_email="maintainers@avp-stack.org",
    description="Launch files, parameter files, the avp command line (launch, demo) and rendering.",
    license="Apache-2.0",
    entry_points={"console_scripts": ["scene_node = avp_bringup.scene_node:main"]},
)
