from setuptools import find_packages, setup

package_name = "avp_predictors"

setup(
    name=package_name,
    version="0.17.0",
    packages=find_packages(exclude=["test"]),
    package_data={package_name: ["models/*"]},
    data_files=[
        ("share/ament_index/resource_index/packages", ["resource/" + package_name]),
        ("share/" + package_name, ["package.xml"]),
    ],
    install_requires=["setuptools"],
    zip_safe=True,
    maintainer="AVP stack maintainers",
    maintainer_email="maintainers@avp-stack.org",
    description="ROS-free prediction of the other cars.",
    license="Apache-2.0",
    entry_points={"console_scripts": []},
)
