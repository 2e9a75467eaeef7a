"""ament_python packaging for catheter_control; also installs with plain pip."""

from pathlib import Path

from setuptools import find_packages, setup

PACKAGE = "catheter_control"

setup(
    name=PACKAGE,
    version="0.1.0",
    packages=find_packages(exclude=["test", "tests"]),
    # The shipped models (manifest + hashed weights) travel inside the package.
    package_data={PACKAGE: ["py.typed", "data/*/*", "urdf/*.urdf", "foxglove/*.json"]},
    data_files=[
        # The ament resource marker and package.xml are what `ros2 run` and
        # ament_index_python look for; colcon installs them under share/.
        ("share/ament_index/resource_index/packages", ["resource/" + PACKAGE]),
        ("share/" + PACKAGE, ["package.xml"]),
        # `ros2 launch catheter_control sim.launch.py` (and rig.launch.py) look here.
        (
            "share/" + PACKAGE + "/launch",
            [str(p) for p in sorted(Path("launch").glob("*.launch.py"))],
        ),
        # The robot model where package://catheter_control/urdf/catheter.urdf resolves, and the
        # Foxglove layout beside it (both also inside the Python package, for the live view).
        ("share/" + PACKAGE + "/urdf", [PACKAGE + "/urdf/catheter.urdf"]),
        ("share/" + PACKAGE + "/foxglove", [PACKAGE + "/foxglove/catheter_layout.json"]),
    ],
    install_requires=["setuptools"],
    zip_safe=False,
    maintainer="catheter maintainers",
    maintainer_email="maintainers@users.noreply.example",
    description=(
        "Control side of the PAM catheter: compensator, recorder, ope"
        "n-loop excitation, follow_trajectory and bring-up."
    ),
    license="Apache-2.0",
    python_requires=">=3.10",
    entry_points={
        "console_scripts": [
            "compensator = catheter_control.compensator_node:main",
            "recorder = catheter_control.recorder_node:main",
            "excite = catheter_control.excite_node:main",
            "follow_trajectory = catheter_control.follow_trajectory:entry",
            "bringup = catheter_control.bringup:main",
            "commission = catheter_control.commission:entry",
            "bag_play = catheter_control.bag_play:entry",
            "live_view = catheter_control.live_view:entry",
            "tip_tf = catheter_control.tip_tf:main",
        ],
    },
)
