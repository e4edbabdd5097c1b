from glob import glob

from setuptools import find_packages, setup

package_name = "avp_experiment"

setup(
    name=package_name,
    version="0.17.0",
    packages=find_packages(exclude=["test"]),
    data_files=[
        ("share/ament_index/resource_index/packages", ["resource/" + package_name]),
        ("share/" + package_name, ["package.xml", "README.md"]),
        ("share/" + package_name + "/config/suites", glob("config/suites/*.yaml")),
        ("share/" + package_name + "/config/suites/methods", glob("config/suites/methods/*.yaml")),
    ],
    install_requires=["setuptools"],
    zip_safe=True,
    maintainer="AVP stack maintainers",
    maintainer_email="maintainers@avp-stack.org",
    description="The experiment (ROS-free): the runner over seeds and methods, records, suites, sweeps, Ray backend.",
    license="Apache-2.0",
    entry_points={"console_scripts": []},
)
