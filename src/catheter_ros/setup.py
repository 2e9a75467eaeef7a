"""ament_python packaging for catheter_ros; also installs with plain pip."""

from setuptools import find_packages, setup

PACKAGE = "catheter_ros"

setup(
    name=PACKAGE,
    version="0.1.0",
    packages=find_packages(exclude=["test", "tests"]),
    package_data={PACKAGE: ["py.typed", "fastdds_loopback.xml"]},
    data_files=[
        # The ament resource marker and package.xml are what ament_index_python looks for.
        ("share/ament_index/resource_index/packages", ["resource/" + PACKAGE]),
        ("share/" + PACKAGE, ["package.xml"]),
    ],
    install_requires=["setuptools"],
    zip_safe=False,
    maintainer="catheter maintainers",
    maintainer_email="maintainers@users.noreply.example",
    description=(
        "ROS 2 plumbing every catheter node shares: process entry, real-time loop, strict "
        "parameters, QoS, lifecycle, diagnostics and message conversion."
    ),
    license="Apache-2.0",
    python_requires=">=3.10",
)
