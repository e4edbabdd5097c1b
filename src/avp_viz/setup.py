from glob import glob

from setuptools import find_packages, setup

package_name = "avp_viz"

setup(
    name=package_name,
    version="0.17.0",
    packages=find_packages(exclude=["test"]),
    data_files=[
        ("share/ament_index/resource_index/packages", ["resource/" + package_name]),
        ("share/" + package_name, ["package.xml", "README.md"]),
        ("share/" + package_name + "/config", glob("config/*.yaml")),
    ],
    install_requires=["setuptools"],
    zip_safe=True,
    maintainer="AVP stack maintainers",
    maintainer_email="maintainers@avp-stack.org",
    description="The viewers: scene node (/tf, 3-D markers), Foxglove bridge, top-down renderer, episode GIF.",
    license="Apache-2.0",
    entry_points={"console_scripts": ["scene_node = avp_viz.scene_node:main"]},
)
