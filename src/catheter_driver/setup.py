"""ament_python packaging for catheter_driver; also installs with plain pip."""

from pathlib import Path

from setuptools import find_packages, setup

PACKAGE = "catheter_driver"

setup(
    name=PACKAGE,
    version="0.1.0",
    packages=find_packages(exclude=["test", "tests"]),
    package_data={PACKAGE: ["py.typed"]},
    data_files=[
        # The ament resource marker and package.xml are what `ros2 run` and
        # ament_index_python look for; colcon installs them under share/.
        ("share/ament_index/resource_index/packages", ["resource/" + PACKAGE]),
        ("share/" + PACKAGE, ["package.xml"]),
        # Example parameter files, one per backend (docs/rig.md).
        ("share/" + PACKAGE + "/config", [str(p) for p in sorted(Path("config").glob("*.yaml"))]),
    ],
    install_requires=["setuptools"],
    zip_safe=False,
    maintainer="catheter maintainers",
    maintainer_email="maintainers@users.noreply.example",
    description=(
        "Hardware side of the PAM catheter: device drivers and the simulated hardware node."
    ),
    license="Apache-2.0",
    python_requires=">=3.10",
    entry_points={
        "console_scripts": [
            "sim_hardware = catheter_driver.sim_hardware_node:main",
            "valve_driver = catheter_driver.valve_driver_node:main",
            "laser_angle = catheter_driver.laser_angle_node:main",
        ],
    },
)
