from glob import glob

from setuptools import find_packages, setup

package_name = "avp_perception"

setup(
    name=package_name,
    version="0.17.0",
    packages=find_packages(exclude=["test"]),
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
    description="The ego's perception and prediction nodes and the pipeline that composes them (paper §V-A..C).",
    license="Apache-2.0",
    entry_points={"console_scripts": [
        "belief_node = avp_perception.belief_node:main",
        "prediction_node = avp_perception.prediction_node:main",
    ]},
)
