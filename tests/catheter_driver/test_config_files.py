"""The example parameter files must name real backends and real options: they do not rot."""

from pathlib import Path

import pytest
import yaml

from catheter_driver.devices.factory import LASER_ADCS, TRANSMITTERS, VALVES, backend_params

CONFIG = Path(__file__).resolve().parents[2] / "src" / "catheter_driver" / "config"
TABLES = {"valve": VALVES, "transmitter": TRANSMITTERS, "adc": LASER_ADCS}
FILES = sorted(CONFIG.glob("*.yaml"))


def test_there_is_one_file_per_backend() -> None:
    names = {p.stem for p in FILES}
    assert {"valve_driver_canopen", "valve_driver_dac_serial"} <= names
    assert {"laser_angle_adc_serial", "laser_angle_adc_can"} <= names


@pytest.mark.parametrize("path", FILES, ids=lambda p: p.name)
def test_every_device_option_is_known_to_its_backend(path: Path) -> None:
    ((_node, body),) = yaml.safe_load(path.read_text()).items()
    params = body["ros__parameters"]
    devices = [key for key in params if key in TABLES]
    assert devices, f"{path.name} configures no device"
    for prefix in devices:
        options = dict(params[prefix])
        backend = options.pop("backend")
        known = backend_params(TABLES[prefix], backend)
        unknown = set(options) - set(known)
        assert not unknown, f"{path.name}: {prefix}.{sorted(unknown)} unknown to {backend}"
    # Safety: no example file may allow more than the thesis's 3 bar.
    assert params.get("max_pressure_pa", 3e5) <= 3e5
