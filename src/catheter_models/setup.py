"""ament_python packaging for catheter_models; also installs with plain pip."""

from setuptools import find_packages, setup

PACKAGE = "catheter_models"

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
    ],
    install_requires=["setuptools"],
    # The lab's refits on a Ray cluster (`catheter-lab explain --ray ADDRESS`); never needed
    # by the graph. The version is the one requirements-dev.txt locks and the tests run.
    extras_require={"ray": ["ray==2.60.0"]},
    zip_safe=False,
    maintainer="catheter maintainers",
    maintainer_email="maintainers@users.noreply.example",
    description=(
        "Science core of the PAM catheter stack: signals, metrics, pl"
        "ant simulation, geometry, bag I/O. Imports no rclpy."
    ),
    license="Apache-2.0",
    python_requires=">=3.10",
    entry_points={
        "console_scripts": [
            "catheter-lab = catheter_models.cli:main",
        ],
    },
)
