from glob import glob

from setuptools import find_packages, setup

package_name = "avp_planner"

setup(
    name=package_name,
    version="0.17.0",
    packages=find_packages(exclude=["test"]),
    package_data={package_name: ["maps/*.yaml", "models/*"]},
    data_files=[
        ("share/ament_index/resource_index/packages", ["resource/" + package_name]),
        ("share/" + package_name, ["package.xml"]),
        ("share/" + package_name + "/config", glob("config/*.yaml")),
        ("share/" + package_name + "/config/profiles", glob("config/profiles/*.yaml")),
        ("share/" + package_name + "/launch", glob("launch/*.launch.py")),
    ],
    install_requires=["setuptools"],
    zip_safe=True,
    maintainer="AVP stack maintainers",
    maintainer_email="maintainers@avp-stack.org",
    description="Ego planner (paper §V-D); for now a scripted driver node.",
    license="Apache-2.0",
    entry_points={"console_scripts": [
        "planner = avp_planner.planner_node:main",
        "scripted_driver = avp_planner.scripted_driver_node:main",
        "minimal_planner = avp_planner.examples.minimal_planner:main",
        "reservation = avp_planner.reservation_node:main",
        "v2v = avp_planner.v2v_node:main",
    ]},
)
