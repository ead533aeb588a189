"""ament_python package ssa_fusion (see README.md)."""

from glob import glob

from setuptools import find_packages, setup

package_name = "ssa_fusion"

setup(
    name=package_name,
    version="0.1.0",
    packages=find_packages(exclude=["test", "test.*"]),
    package_data={"ssa_fusion.formats": ["data/*.gfc", "data/README.md"]},  # EGM96
    data_files=[
        ("share/ament_index/resource_index/packages", ["resource/" + package_name]),
        ("share/" + package_name, ["package.xml"]),
        ("share/" + package_name + "/launch", glob("launch_scripts/*.launch.py")),
        ("share/" + package_name + "/config",
         glob("config/*.yaml") + glob("config/*.json")),  # params; the Foxglove layout
        ("share/" + package_name + "/config/catalogs", glob("config/catalogs/*")),
        ("share/" + package_name + "/config/sites", glob("config/sites/*.yaml")),
    ],
    install_requires=["setuptools"],
    zip_safe=True,
    maintainer="ssa_fusion developers",
    maintainer_email="dev@ssa-fusion.invalid",
    description="Hankel-DMD surrogate + Keplerian EKF for satellites observed with gaps",
    license="Apache-2.0",
    python_requires=">=3.10",
    entry_points={
        "console_scripts": [
            "ssa-fusion = ssa_fusion.apps.cli:main",
            # nodes.entry prepares the process (signals, BLAS threads) before it imports the
            # node module, then runs ssa_fusion.nodes.<node>:main
            "sensor_sim = ssa_fusion.nodes.entry:sensor_sim",
            "surrogate = ssa_fusion.nodes.entry:surrogate",
            "filter = ssa_fusion.nodes.entry:filter_node",
            "recorder = ssa_fusion.nodes.entry:recorder",
            "foxglove_bridge = ssa_fusion.nodes.entry:foxglove_bridge",
            "catalog_filter = ssa_fusion.nodes.entry:catalog_filter",
            "catalog_surrogate = ssa_fusion.nodes.entry:catalog_surrogate",
            "conjunction = ssa_fusion.nodes.entry:conjunction",
        ],
    },
)
