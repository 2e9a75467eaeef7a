"""The plant contract (docs/simulated_rig.md, "Your own plant"): loading, checks, the default.

A lab names its plant as ``module:factory`` or ``path/to/file.py:factory``; everything that
can go wrong on the way (a bad spec, a module or factory not found, a factory that raises or
returns something else, a non-finite value, a plant slower than its rate) must be refused or
stopped with a reason that says which, and the shipped plant must stay the default, unchanged.
"""

from __future__ import annotations

import math
import textwrap
from collections.abc import Callable
from dataclasses import astuple
from pathlib import Path

import numpy as np
import pytest

from catheter_driver.sim_hardware import SimHardware
from catheter_models.geometry import LaserGeometry
from catheter_models.plant import (
    CheckedPlant,
    Plant,
    PlantConfig,
    PlantError,
    PlantModel,
    PlantRunError,
    ShippedPlant,
    load_plant,
    make_plant,
)
from catheter_models.plant.interface import RATE_RANGE_HZ, RATE_WINDOW_S

CONFIG = PlantConfig.thesis_rig()
STRAIGHT_M = float(CONFIG.rig["straight_distance_m"])


def _plant_file(tmp_path: Path, body: str, name: str = "my_plant.py") -> Path:
    path = tmp_path / name
    path.write_text(textwrap.dedent(body))
    return path


class _Toy:
    """A minimal plant of the contract: bend follows the command, no noise."""

    def __init__(self, rate_hz: float = 100.0) -> None:
        self.rate_hz = rate_hz
        self.k = 0

    def reset(self) -> None:
        self.k = 0

    def step(self, pressure_command_pa: float) -> tuple[float, float]:
        self.k += 1
        return pressure_command_pa, pressure_command_pa * 1e-6


class _Clock:
    """A wall clock the test moves: what a plant's steps cost, without sleeping."""

    def __init__(self) -> None:
        self.now_s = 0.0

    def __call__(self) -> float:
        return self.now_s


# -- loading ---------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("spec", "says"),
    [
        ("foreign_plants.plugin", "is not 'module:factory' or 'path/to/file.py:factory'"),
        (":boucwen", "is not 'module:factory'"),
        ("foreign_plants.plugin:", "is not 'module:factory'"),
        ("foreign plants:boucwen", "is not a module path"),
        ("foreign_plants.plugin:1st", "is not a Python name"),
        ("no_such_lab.rod:make_plant", "plant module 'no_such_lab.rod' not found"),
        ("foreign_plants.plugin:no_such", "has no attribute 'no_such'"),
        ("foreign_plants.plugin:RATE_HZ", "RATE_HZ is float 250.0, not callable"),
        ("math:sqrt", "plant factory 'math:sqrt' raised TypeError"),
        ("builtins:object", "does not meet the plant contract"),
    ],
)
def test_a_plant_that_cannot_be_loaded_is_refused_with_the_reason(spec: str, says: str) -> None:
    with pytest.raises(PlantError) as err:
        load_plant(spec)
    assert says in str(err.value), str(err.value)


def test_a_module_not_found_names_pythonpath() -> None:
    with pytest.raises(PlantError, match="is its directory on PYTHONPATH"):
        load_plant("no_such_lab.rod:make_plant")


def test_a_plant_file_is_loaded_by_path_and_a_missing_one_named(tmp_path: Path) -> None:
    path = _plant_file(
        tmp_path,
        """
        class Rod:
            rate_hz = 500.0
            def reset(self):
                pass
            def step(self, pressure_command_pa):
                return pressure_command_pa, 0.0

        def make_plant():
            return Rod()
        """,
    )
    plant = load_plant(f"{path}:make_plant")
    assert isinstance(plant, PlantModel)
    assert plant.rate_hz == 500.0
    with pytest.raises(PlantError, match="does not exist"):
        load_plant(f"{tmp_path / 'missing.py'}:make_plant")
    broken = _plant_file(tmp_path, "raise RuntimeError('no licence for the rod solver')\n", "b.py")
    with pytest.raises(PlantError, match="RuntimeError: no licence for the rod solver"):
        load_plant(f"{broken}:make_plant")


@pytest.mark.parametrize(
    ("body", "says"),
    [
        (
            "def make():\n    raise RuntimeError('calibration file missing')\n",
            "raised RuntimeError: calibration file missing",
        ),
        ("def make():\n    return 42\n", "no reset() method; no step() method; no rate_hz"),
        (
            "class P:\n    rate_hz = 'fast'\n    def reset(self): pass\n"
            "    def step(self, p): return p, 0.0\ndef make():\n    return P()\n",
            "rate_hz is str 'fast', not a number",
        ),
        (
            "class P:\n    rate_hz = 20000.0\n    def reset(self): pass\n"
            "    def step(self, p): return p, 0.0\ndef make():\n    return P()\n",
            f"outside the rates the rig runs at [{RATE_RANGE_HZ[0]:g}, {RATE_RANGE_HZ[1]:g}] Hz",
        ),
    ],
    ids=["raises", "not_a_plant", "rate_not_a_number", "rate_out_of_range"],
)
def test_a_factory_that_raises_or_breaks_the_contract_is_refused(
    tmp_path: Path, body: str, says: str
) -> None:
    path = _plant_file(tmp_path, body)
    with pytest.raises(PlantError) as err:
        make_plant(f"{path}:make", CONFIG)
    assert says in str(err.value), str(err.value)


def test_the_foreign_plants_plugin_meets_the_contract_and_reset_replays() -> None:
    from foreign_plants.plugin import FACTORIES

    for name in FACTORIES:
        plant = load_plant(f"foreign_plants.plugin:{name}")
        assert isinstance(plant, PlantModel), name
        commands = np.concatenate([np.full(100, 2.0e5), np.zeros(100)])
        first = [plant.step(float(u)) for u in commands]
        plant.reset()
        again = [plant.step(float(u)) for u in commands]
        assert first == again, f"{name}: reset() is not back to rest"
        pressure, bend = np.array(first).T
        # The valve reaches 2 bar and the catheter bends, then both come back.
        assert abs(pressure[90:100].mean() - 2.0e5) < 0.05e5, name
        assert math.degrees(bend[99]) > 5.0 and abs(math.degrees(bend[-1])) < 5.0, name


# -- checks at rest (configure) --------------------------------------------------------------


def test_a_plant_non_finite_at_rest_is_refused_before_it_runs(tmp_path: Path) -> None:
    path = _plant_file(
        tmp_path,
        """
        class P:
            rate_hz = 250.0
            def reset(self):
                pass
            def step(self, pressure_command_pa):
                return 0.0, float("nan")

        def make():
            return P()
        """,
    )
    with pytest.raises(PlantError, match=r"non-finite bend_rad \(nan\) at sample 1"):
        make_plant(f"{path}:make", CONFIG)


def test_a_plant_slower_than_its_rate_at_rest_is_refused(tmp_path: Path) -> None:
    # 5 ms of real sleep per step at 1 kHz: five periods per step, at any host's speed.
    path = _plant_file(
        tmp_path,
        """
        import time
        class P:
            rate_hz = 1000.0
            def reset(self):
                pass
            def step(self, pressure_command_pa):
                time.sleep(0.005)
                return 0.0, 0.0

        def make():
            return P()
        """,
    )
    with pytest.raises(PlantError) as err:
        make_plant(f"{path}:make", CONFIG)
    assert "cannot keep its rate" in str(err.value)
    assert "longer than its period of 1.000 ms at 1000 Hz" in str(err.value)


def test_settings_only_the_shipped_plant_takes_are_named_not_dropped() -> None:
    config = (
        PlantConfig.thesis_rig(seed=3)
        .with_effect("creep", fraction=0.2)
        .with_rig(valve_time_constant_s=0.01, straight_distance_m=0.06, sample_rate_hz=250.0)
    )
    with pytest.raises(PlantError) as err:
        make_plant("foreign_plants.plugin:boucwen", config)
    message = str(err.value)
    for name in ("rig.valve_time_constant_s", "effects.creep.enabled", "effects.creep.fraction"):
        assert name in message, message
    assert "seed" in message
    # The laser's straight-tip distance and a rate equal to the plant's own apply to any plant.
    assert "straight_distance_m" not in message and "sample_rate_hz" not in message
    with pytest.raises(PlantError, match=r"rig\.sample_rate_hz"):
        make_plant("foreign_plants.plugin:boucwen", CONFIG.with_rig(sample_rate_hz=1000.0))


# -- checks while running --------------------------------------------------------------------


def _checked(plant: PlantModel, clock: Callable[[], float] | None = None) -> CheckedPlant:
    if clock is None:
        return CheckedPlant(plant, "toy", STRAIGHT_M)
    return CheckedPlant(plant, "toy", STRAIGHT_M, clock=clock)


@pytest.mark.parametrize(
    ("output", "says"),
    [
        ((1.0, math.nan), "non-finite bend_rad (nan) at sample 3"),
        ((math.inf, 0.0), "non-finite pressure_measured_pa (inf) at sample 3"),
        ("1.0, 0.0", "returned str '1.0, 0.0' at sample 3, not (pressure_measured_pa, bend_rad)"),
        ((1.0, 0.0, 0.0), "not (pressure_measured_pa, bend_rad)"),
        ((1.0, None), "bend_rad = NoneType None at sample 3, not a number"),
    ],
)
def test_a_bad_output_mid_run_stops_the_plant_and_vents(output: object, says: str) -> None:
    toy = _Toy()
    good = toy.step

    def step(pressure_command_pa: float) -> object:
        return output if toy.k >= 2 else good(pressure_command_pa)

    toy.step = step  # type: ignore[assignment, method-assign]
    hw = SimHardware(CONFIG, plant=_checked(toy))
    assert hw.command(1.0e5, now_s=0.0)
    hw.step(0.001)
    hw.step(0.002)
    toy.k = 2
    with pytest.raises(PlantRunError) as err:
        hw.step(0.003)
    assert says in str(err.value), str(err.value)
    # Stopped for good, vented as the watchdog vents, and every later command refused.
    assert hw.fault == str(err.value)
    assert hw.venting and hw.command_pa == 0.0
    assert not hw.command(1.0e5, now_s=0.004)
    assert "the plant was stopped" in hw.last_refusal
    with pytest.raises(PlantRunError):
        hw.step(0.005)


def test_a_step_that_raises_is_stopped_with_its_exception() -> None:
    toy = _Toy()

    def step(pressure_command_pa: float) -> tuple[float, float]:
        raise ZeroDivisionError("rod solver diverged")

    toy.step = step  # type: ignore[method-assign]
    hw = SimHardware(CONFIG, plant=_checked(toy))
    with pytest.raises(PlantRunError, match=r"step\(\) raised ZeroDivisionError at sample 1"):
        hw.step(0.0)
    assert "rod solver diverged" in hw.fault and hw.venting


def _timed_toy(clock: _Clock, cost_periods: Callable[[int], float]) -> _Toy:
    """A toy whose k-th step costs ``cost_periods(k)`` of its periods on ``clock``."""
    toy = _Toy(rate_hz=100.0)
    good = toy.step

    def step(pressure_command_pa: float) -> tuple[float, float]:
        clock.now_s += cost_periods(toy.k + 1) / toy.rate_hz
        return good(pressure_command_pa)

    toy.step = step  # type: ignore[method-assign]
    return toy


def test_a_plant_slower_than_real_time_over_a_window_is_stopped_and_vented() -> None:
    clock = _Clock()
    # Fast enough for half a second, then 1.5 periods a step: behind for good.
    toy = _timed_toy(clock, lambda k: 0.1 if k <= 50 else 1.5)
    hw = SimHardware(CONFIG, plant=_checked(toy, clock))
    hw.command(2.0e5, now_s=0.0)
    window = round(RATE_WINDOW_S * toy.rate_hz)
    with pytest.raises(PlantRunError) as err:
        for k in range(1, 10 * window):
            hw.step(k * 0.001)
    # The first second (50 quick steps, 50 slow: 80 % of real time) kept up; the second,
    # all slow, did not, and is judged as it ends.
    assert toy.k == 2 * window
    assert "cannot keep its rate" in str(err.value)
    assert "10.000 ms" in str(err.value)
    assert hw.venting and hw.command_pa == 0.0


def test_a_single_slow_step_is_absorbed_not_stopped() -> None:
    clock = _Clock()
    # One step of half a window (a garbage collection, a busy host), the rest quick.
    toy = _timed_toy(clock, lambda k: 50.0 if k == 30 else 0.1)
    hw = SimHardware(CONFIG, plant=_checked(toy, clock))
    hw.command(2.0e5, now_s=0.0)
    for k in range(1, 3 * round(RATE_WINDOW_S * toy.rate_hz)):
        hw.step(k * 0.001)
    assert not hw.fault


def test_a_step_that_does_not_return_counts_as_too_slow_while_it_runs() -> None:
    clock = _Clock()
    toy = _Toy(rate_hz=100.0)
    seen: list[str] = []
    hw: SimHardware

    def step(pressure_command_pa: float) -> tuple[float, float]:
        clock.now_s += 0.5 * RATE_WINDOW_S
        seen.append(hw.stuck_reason())  # what another thread sees while the step runs
        clock.now_s += RATE_WINDOW_S
        seen.append(hw.stuck_reason())
        hw.stop(seen[-1])
        return 0.0, 0.0

    toy.step = step  # type: ignore[method-assign]
    hw = SimHardware(CONFIG, plant=_checked(toy, clock))
    with pytest.raises(PlantRunError, match=r"one step has run for 1\.50 s"):
        hw.step(0.0)
    assert seen[0] == "" and "cannot keep its rate" in seen[1]
    assert hw.venting and not hw.stuck_reason(), "no step runs any more"


# -- what the rig publishes ------------------------------------------------------------------


def test_distance_is_derived_from_the_bend_with_the_laser_geometry() -> None:
    geom = LaserGeometry()
    checked = _checked(_Toy())
    for bend_deg in (-5.0, 0.0, 0.01, 10.0, 30.0, 50.0):
        distance_m = checked.distance_m(math.radians(bend_deg))
        back_deg = math.degrees(geom.displacement_to_angle_rad(STRAIGHT_M - distance_m))
        assert back_deg == pytest.approx(bend_deg, abs=1e-9)
    # Beyond the laser's range the distance clips where its 0-10 V output ends.
    assert checked.distance_m(math.radians(65.0)) == pytest.approx(geom.voltage_to_distance_m(0.0))
    sample = checked.step_sample(2.0e5)
    assert sample.angle_rad == pytest.approx(0.2)
    assert sample.pressure_measured_pa == 2.0e5
    assert math.isnan(sample.true_angle_rad) and math.isnan(sample.muscle_pressure_pa)
    assert sample.t_s == pytest.approx(0.01)


# -- the shipped plant stays the default -----------------------------------------------------


def test_the_shipped_plant_meets_the_contract() -> None:
    shipped = ShippedPlant(CONFIG)
    reference = Plant(CONFIG)
    assert isinstance(shipped, PlantModel)
    assert shipped.rate_hz == CONFIG.rig["sample_rate_hz"]
    for command_pa in (0.0, 1.5e5, 3.0e5):
        sample = reference.step(command_pa)
        assert shipped.step(command_pa) == (sample.pressure_measured_pa, sample.angle_rad)


def test_the_default_plant_streams_the_same_samples_bit_for_bit() -> None:
    """sim_hardware's default (checked, probed at rest) gives what Plant gives, streamed or
    batch: the contract's checks and probe leave the shipped plant's samples unchanged."""
    config = PlantConfig.thesis_rig(seed=4).with_effect("pneumatic_lag")
    commands = np.concatenate([np.linspace(0.0, 2.5e5, 300), np.full(200, 0.4e5)])
    batch = Plant(config).simulate(commands)
    for hw in (SimHardware(config), SimHardware(config, plant=make_plant("", config))):
        streamed = []
        for k, command_pa in enumerate(commands):
            hw.command(float(command_pa), now_s=k * 0.004)
            streamed.append(hw.step(k * 0.004 + 0.001))
        plain = Plant(config)
        assert [astuple(s) for s in streamed] == [astuple(plain.step(float(u))) for u in commands]
        np.testing.assert_array_equal([s.angle_rad for s in streamed], batch.angle_rad)
        np.testing.assert_array_equal(
            [s.pressure_measured_pa for s in streamed], batch.pressure_measured_pa
        )
        np.testing.assert_array_equal([s.distance_m for s in streamed], batch.distance_m)


# -- the node: configure refuses, a running fault deactivates -----------------------------------

_NAN_AFTER_50 = """
class P:
    rate_hz = 250.0
    def __init__(self):
        self.k = 0
    def reset(self):
        self.k = 0
    def step(self, pressure_command_pa):
        self.k += 1
        return pressure_command_pa, (float("nan") if self.k > 50 else 0.0)

def make():
    return P()
"""


def test_the_node_fails_configure_with_the_plant_s_reason(tmp_path: Path) -> None:
    from rclpy.lifecycle import TransitionCallbackReturn
    from test_node_conventions import built

    from catheter_driver.sim_hardware_node import SimHardwareNode

    path = _plant_file(tmp_path, "def make():\n    raise RuntimeError('no rod model fitted')\n")
    with built(SimHardwareNode, "-p", f"plant:={path}:make", "-p", "rt_priority:=0") as node:
        assert node.trigger_configure() == TransitionCallbackReturn.FAILURE
        assert node.transition_failure.startswith("configure failed: plant factory")
        assert "raised RuntimeError: no rod model fitted" in node.transition_failure
        assert node.hw is None


def test_the_node_runs_a_plant_of_its_own_at_its_rate() -> None:
    from rclpy.lifecycle import TransitionCallbackReturn
    from test_node_conventions import built

    from catheter_driver.sim_hardware_node import SimHardwareNode

    spec = "foreign_plants.plugin:maxwell_slip"
    with built(SimHardwareNode, "-p", f"plant:={spec}", "-p", "rt_priority:=0") as node:
        assert node.trigger_configure() == TransitionCallbackReturn.SUCCESS
        assert node.hw is not None and not node.hw.plant.shipped
        assert node.rate_hz == 250.0 and node.hw.plant.name == repr(spec)


def test_a_plant_breaking_its_contract_while_running_deactivates_the_node(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    import time

    from rclpy.lifecycle import TransitionCallbackReturn
    from test_node_conventions import built

    from catheter_driver import sim_hardware_node
    from catheter_driver.sim_hardware_node import SimHardwareNode

    published: list[tuple[int, str, dict[str, object]]] = []

    def capture(_pub: object, _node: object, *, level: int, message: str, **kw: object) -> None:
        values = kw.get("values")
        published.append((level, message, dict(values) if isinstance(values, dict) else {}))

    monkeypatch.setattr(sim_hardware_node.diagnostics, "publish_status", capture)
    path = _plant_file(tmp_path, _NAN_AFTER_50)
    with built(SimHardwareNode, "-p", f"plant:={path}:make", "-p", "rt_priority:=0") as node:
        assert node.trigger_configure() == TransitionCallbackReturn.SUCCESS
        assert node.trigger_activate() == TransitionCallbackReturn.SUCCESS
        hw = node.hw
        assert hw is not None
        hw.command(1.0e5, now_s=time.monotonic())
        deadline = time.monotonic() + 10.0
        while not hw.fault and time.monotonic() < deadline:
            time.sleep(0.02)
        assert "non-finite bend_rad (nan) at sample 51" in hw.fault
        assert hw.venting and hw.command_pa == 0.0
        node._watch_plant()  # the executor's timer
        assert node._state_machine.current_state[1] == "inactive"
        assert node.active_loop is None
        error = sim_hardware_node.diagnostics.ERROR
        assert published and published[-1][0] == error
        assert published[-1][1] == f"plant stopped, valve vented: {hw.fault}"
        assert published[-1][2]["venting"] is True
        # It stays stopped: activating again is refused with the reason until cleanup.
        assert node.trigger_activate() == TransitionCallbackReturn.FAILURE
        assert "the plant was stopped" in node.transition_failure
        assert node.trigger_cleanup() == TransitionCallbackReturn.SUCCESS
        assert node.trigger_configure() == TransitionCallbackReturn.SUCCESS
        assert node.hw is not None and not node.hw.fault


# -- the emulated rig --------------------------------------------------------------------------


def test_the_emulated_rig_refuses_a_plant_before_anything_starts(
    capsys: pytest.CaptureFixture[str],
) -> None:
    from catheter_driver.emulators import rig

    assert rig.main(["--plant", "no_such_lab.rod:make_plant"]) == 2
    assert "plant module 'no_such_lab.rod' not found" in capsys.readouterr().err
    # --plant-param sets the shipped plant: with a plant of your own it is named, not dropped.
    argv = ["--plant", "foreign_plants.plugin:boucwen", "--plant-param", "creep.enabled=true"]
    assert rig.main(argv) == 2
    assert "effects.creep.enabled" in capsys.readouterr().err


def test_the_emulated_rig_serves_a_plant_of_its_own_and_stops_one_that_breaks(
    tmp_path: Path,
) -> None:
    import time

    from catheter_driver.emulators.rig_core import EmulatedRig

    spec = "foreign_plants.plugin:boucwen_tip"
    with EmulatedRig(CONFIG, plant=make_plant(spec, CONFIG)) as rig:
        assert rig.sample_rate_hz == 250.0
        rig.command(2.0e5)
        time.sleep(0.5)
        state = rig.state()
        assert state["plant"] == repr(spec) and state["fault"] == ""
        assert state["plant_steps"] > 0 and state["muscle_pa"] is None
        assert state["angle_deg"] is None, "a plant of your own gives no truth"
        assert abs(state["measured_pa"] - 2.0e5) < 0.05e5
        sample = rig.latest
        assert sample is not None and math.degrees(sample.angle_rad) > 5.0

    path = _plant_file(tmp_path, _NAN_AFTER_50)
    with EmulatedRig(CONFIG, plant=make_plant(f"{path}:make", CONFIG)) as rig:
        rig.command(1.0e5)
        deadline = time.monotonic() + 10.0
        while rig.running and time.monotonic() < deadline:
            time.sleep(0.02)
        assert not rig.running
        assert "non-finite bend_rad (nan) at sample 51" in rig.check_plant()
        assert rig.hw.venting and rig.hw.command_pa == 0.0
        assert rig.state()["plant_steps"] == 51
        assert not rig.command(1.0e5), "a stopped plant takes no set-point"
