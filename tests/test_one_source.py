"""The contract's numbers have one source: ``catheter_models/contract.py``.

A pressure limit that can be changed in one place and not in another is a safety defect, and
a rate typed in two places drifts. So every ``.py`` under ``src/`` (launch files included)
except ``contract.py`` is read with ``ast`` and fails the test, naming ``file:line``, where it:

* holds a number equal to ``MAX_PRESSURE_PA`` (3 bar), ``PRESSURE_LIMIT_HARD_PA`` (6 bar) or
  ``MAX_SLEW_PA_PER_S`` (20 bar/s), in any spelling (``3.0e5``, ``3e5``, ``300_000``,
  ``300000.0``, ...), or a numeric string equal to one as a named default (a launch
  argument's ``default_value``);
* gives ``COMMAND_TIMEOUT_S`` (0.1 s) to something named as the command watchdog
  (``watchdog_s``, ``command_timeout_s``): 0.1 is too common a number to flag everywhere;
* gives a 250 (``250``, ``250.0``, ``"250.0"``) to something named as a rate: a default of a
  function parameter, a keyword argument or a dataclass field whose name contains ``rate_hz``,
  a value assigned to a name containing ``RATE_HZ``, or the default of a declaration whose
  first argument names it (``BoundedParam("control_rate_hz", ...)``, ``add_argument("--rate-hz",
  default=...)``, ``DeclareLaunchArgument("rate_hz", default_value=...)``).

Words are not numbers: docstrings and comments may say "3 bar" or "250 Hz".

What is deliberately not a contract number:

* a device's ``full_scale_pa`` (an analog output's span, e.g. 0..6 bar on the CANopen module):
  the hardware's property, which must not move if the contract's parameter bound does;
* the sanity ranges of rate parameters (``BoundedParam("rate_hz", ..., 10.0, 5000.0, ...)``):
  they bound what a user may ask for, not what the contract says, and stay literal;
* other 250s (a window of 250 samples, a bus address 250): only a 250 named as a rate counts.

The behaviour is checked too: each node's declared ``max_pressure_pa`` default and bound and its
rate default are the contract's, so are the plant's ceiling and rate, model evaluation's
ceiling and the lab CLI's resampling rate; the rclpy QoS profiles and the profiles a bag's
``metadata.yaml`` records are the contract's QoS specs.
"""

from __future__ import annotations

import argparse
import ast
import inspect
from collections.abc import Iterator
from pathlib import Path
from types import ModuleType

import pytest
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

from catheter_models import contract
from catheter_models.bag import metadata
from catheter_models.contract import (
    COMMAND_TIMEOUT_S,
    CONTROL_RATE_HZ,
    MAX_PRESSURE_PA,
    MAX_SLEW_PA_PER_S,
    PRESSURE_LIMIT_HARD_PA,
    SENSOR_RATE_HZ,
    QosSpec,
)
from catheter_models.limits import BoundedParam
from catheter_models.plant.config import RIG_PARAMS, PlantConfig

REPO = Path(__file__).resolve().parents[1]
SRC = REPO / "src"
CONTRACT_FILE = SRC / "catheter_models" / "catheter_models" / "contract.py"

LIMITS = {
    MAX_PRESSURE_PA: "MAX_PRESSURE_PA",
    PRESSURE_LIMIT_HARD_PA: "PRESSURE_LIMIT_HARD_PA",
    MAX_SLEW_PA_PER_S: "MAX_SLEW_PA_PER_S",
}
WATCHDOG_NAMES = ("watchdog_s", "command_timeout_s")
"""Names of the command watchdog, whose typed ``COMMAND_TIMEOUT_S`` is a finding."""
RATES = {"CONTROL_RATE_HZ": CONTROL_RATE_HZ, "SENSOR_RATE_HZ": SENSOR_RATE_HZ}
"""By name: the two rates are both 250 Hz today, and either typed is a finding."""

_DEFAULT_KEYWORDS = frozenset({"default", "default_value", "value"})
"""Keywords through which a declaration (``add_argument``, ``DeclareLaunchArgument``,
``declare_parameter``) gives the default of the name in its first argument."""

_NOT_CONTRACT = ("full_scale",)
"""Names whose numbers are a device's property, not the contract's (see the module docstring)."""


def _number(node: ast.AST, *, strings: bool) -> float | None:
    """The value of a numeric literal (or, with ``strings``, of a numeric string), else None."""
    if not isinstance(node, ast.Constant) or isinstance(node.value, bool):
        return None
    if isinstance(node.value, int | float):
        return float(node.value)
    if strings and isinstance(node.value, str):
        try:
            return float(node.value)
        except ValueError:
            return None
    return None


def _target_name(node: ast.AST) -> str | None:
    if isinstance(node, ast.Name):
        return node.id
    if isinstance(node, ast.Attribute):
        return node.attr
    return None


def _named_values(tree: ast.AST) -> Iterator[tuple[str, ast.expr]]:
    """Every (name, value) pair the source gives a default or a value by name."""
    for node in ast.walk(tree):
        if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef | ast.Lambda):
            positional = [*node.args.posonlyargs, *node.args.args]
            for arg, default in zip(
                positional[len(positional) - len(node.args.defaults) :],
                node.args.defaults,
                strict=True,
            ):
                yield arg.arg, default
            for arg, kw_default in zip(node.args.kwonlyargs, node.args.kw_defaults, strict=True):
                if kw_default is not None:
                    yield arg.arg, kw_default
        elif isinstance(node, ast.Assign):
            for target in node.targets:
                name = _target_name(target)
                if name is not None:
                    yield name, node.value
        elif isinstance(node, ast.AnnAssign) and node.value is not None:
            name = _target_name(node.target)
            if name is not None:
                yield name, node.value
        elif isinstance(node, ast.Dict):
            for key, value in zip(node.keys, node.values, strict=True):
                if isinstance(key, ast.Constant) and isinstance(key.value, str):
                    yield key.value, value
        elif isinstance(node, ast.Call):
            for keyword in node.keywords:
                if keyword.arg is not None:
                    yield keyword.arg, keyword.value
            first = node.args[0] if node.args else None
            if isinstance(first, ast.Constant) and isinstance(first.value, str):
                # A declaration: BoundedParam("rate_hz", 250.0, ...), add_argument("--rate-hz",
                # default=...), DeclareLaunchArgument("rate_hz", default_value="250.0").
                if len(node.args) > 1:
                    yield first.value, node.args[1]
                for keyword in node.keywords:
                    if keyword.arg in _DEFAULT_KEYWORDS:
                        yield first.value, keyword.value


def _is_rate_name(name: str) -> bool:
    return "rate_hz" in name.lower().replace("-", "_")


def typed_contract_numbers(source: str, filename: str = "<source>") -> list[str]:
    """``file:line: why`` for every contract number typed in ``source`` (empty if none)."""
    tree = ast.parse(source, filename=filename)
    found: dict[tuple[int, int], str] = {}
    exempt: set[int] = set()
    for name, value in _named_values(tree):
        if any(word in name.lower() for word in _NOT_CONTRACT):
            exempt.add(id(value))
            continue
        number = _number(value, strings=True)
        if number is None:
            continue
        where = (value.lineno, value.col_offset)
        if number in LIMITS:
            found[where] = f"{name} = {number:g} types contract.{LIMITS[number]}"
        elif number == COMMAND_TIMEOUT_S and any(w in name.lower() for w in WATCHDOG_NAMES):
            found[where] = f"{name} = {number:g} types contract.COMMAND_TIMEOUT_S"
        elif _is_rate_name(name) and number in RATES.values():
            rates = " or ".join(f"contract.{k}" for k, v in RATES.items() if v == number)
            found[where] = f"{name} = {number:g} types {rates}"
    for node in ast.walk(tree):
        number = _number(node, strings=False)
        if number in LIMITS and id(node) not in exempt:
            assert isinstance(node, ast.Constant)
            found.setdefault(
                (node.lineno, node.col_offset), f"{number:g} types contract.{LIMITS[number]}"
            )
    return [f"{filename}:{line}: {why}" for (line, _col), why in sorted(found.items())]


def _sources() -> list[Path]:
    return sorted(p for p in SRC.rglob("*.py") if p != CONTRACT_FILE)


def test_no_contract_number_is_typed_outside_the_contract() -> None:
    findings = [
        finding
        for path in _sources()
        for finding in typed_contract_numbers(
            path.read_text(encoding="utf-8"), str(path.relative_to(REPO))
        )
    ]
    assert not findings, "import these from catheter_models.contract:\n" + "\n".join(findings)


# -- the scanner can fail ------------------------------------------------------------------


@pytest.mark.parametrize(
    "source",
    [
        "def f(max_pressure_pa=3.0e5): ...",
        "LIMIT = 300_000",
        "x = g(6e5)",
        "BoundedParam('max_pressure_pa', 0.0, 0.0, 600000.0, 'bound')",
        "DeclareLaunchArgument('max_pressure_pa', default_value='3.0e5')",
        "def f(rate_hz: float = 250.0): ...",
        "DEFAULT_RATE_HZ = 250",
        "BoundedParam('control_rate_hz', 250.0, 10.0, 2000.0, 'rate')",
        "p.add_argument('--rate-hz', type=float, default=250.0)",
        "DeclareLaunchArgument('control_rate_hz', default_value='250.0')",
        "run(sample_rate_hz=250)",
        "class C:\n    rate_hz: float = 250.0",
        "BoundedParam('max_slew_pa_per_s', 20.0e5, 1.0e3, 1.0e8, 'slew')",
        "BoundedParam('watchdog_s', 0.1, 0.01, 5.0, 'vent')",
        "def f(command_timeout_s: float = 0.1): ...",
    ],
)
def test_the_scanner_catches_a_typed_contract_number(source: str) -> None:
    findings = typed_contract_numbers(source, "probe.py")
    assert len(findings) == 1, findings
    assert findings[0].startswith("probe.py:")


def test_the_scanner_names_file_and_line() -> None:
    source = '"""Doc."""\n\nimport x\n\nx.clamp(max_pressure_pa=3.0e5)\n'
    assert typed_contract_numbers(source, "pkg/node.py") == [
        "pkg/node.py:5: max_pressure_pa = 300000 types contract.MAX_PRESSURE_PA"
    ]


def test_words_and_other_numbers_are_not_contract_numbers() -> None:
    source = '''
"""The 3 bar ceiling (3.0e5 Pa, max_pressure_pa=3.0e5) at 250 Hz (rate_hz = 250.0)."""

def f(window: int = 250, full_scale_pa: float = 6.0e5, rate_hz: float = RATE) -> str:
    """Samples 250 times; 6e5 Pa is the span."""
    # max_pressure_pa = 3.0e5 in a comment
    address = 250
    return "max_pressure_pa=3.0e5"

BoundedParam("rate_hz", RATE, 10.0, 250.0, "a range bound is not the default")
'''
    assert typed_contract_numbers(source) == []


# -- the numbers in force are the contract's -------------------------------------------------


def _specs(module: ModuleType) -> dict[str, BoundedParam]:
    """The ParamSpecs a node module declares, by parameter name."""
    return {v.name: v for v in vars(module).values() if isinstance(v, BoundedParam)}


def _node_modules() -> dict[str, ModuleType]:
    from catheter_control import compensator_node, excite_node
    from catheter_driver import laser_angle_node, sim_hardware_node, valve_driver_node

    return {
        "valve_driver": valve_driver_node,
        "laser_angle": laser_angle_node,
        "sim_hardware": sim_hardware_node,
        "compensator": compensator_node,
        "excite": excite_node,
    }


@pytest.mark.parametrize("node", ["valve_driver", "sim_hardware", "compensator", "excite"])
def test_every_node_s_pressure_ceiling_is_the_contract_s(node: str) -> None:
    specs = _specs(_node_modules()[node])
    ceiling = specs["max_pressure_pa"]
    assert ceiling.default == MAX_PRESSURE_PA
    assert ceiling.high == PRESSURE_LIMIT_HARD_PA
    if "min_pressure_pa" in specs:
        assert specs["min_pressure_pa"].high == PRESSURE_LIMIT_HARD_PA


@pytest.mark.parametrize(
    ("node", "parameter", "rate_hz"),
    [
        ("valve_driver", "rate_hz", CONTROL_RATE_HZ),
        ("laser_angle", "rate_hz", SENSOR_RATE_HZ),
        ("compensator", "control_rate_hz", CONTROL_RATE_HZ),
        ("excite", "rate_hz", CONTROL_RATE_HZ),
    ],
)
def test_every_node_s_rate_is_the_contract_s(node: str, parameter: str, rate_hz: float) -> None:
    assert _specs(_node_modules()[node])[parameter].default == rate_hz


@pytest.mark.parametrize(
    ("node", "parameter", "value"),
    [
        ("valve_driver", "max_slew_pa_per_s", MAX_SLEW_PA_PER_S),
        ("compensator", "max_slew_pa_per_s", MAX_SLEW_PA_PER_S),
        ("valve_driver", "watchdog_s", COMMAND_TIMEOUT_S),
        ("sim_hardware", "command_timeout_s", COMMAND_TIMEOUT_S),
    ],
)
def test_every_node_s_slew_and_watchdog_are_the_contract_s(
    node: str, parameter: str, value: float
) -> None:
    assert _specs(_node_modules()[node])[parameter].default == value


def test_the_simulated_rig_plant_and_evaluation_use_the_contract_s_numbers() -> None:
    from catheter_driver.sim_hardware import SimHardware
    from catheter_models.cli import build_parser
    from catheter_models.models import evaluate

    rig = {p.name: p for p in RIG_PARAMS}
    # sim_hardware's rate is the plant's sample rate (rig.sample_rate_hz).
    assert rig["sample_rate_hz"].default == SENSOR_RATE_HZ
    assert rig["valve_max_pressure_pa"].default == MAX_PRESSURE_PA
    config = PlantConfig.thesis_rig()
    assert config.rig["valve_max_pressure_pa"] == MAX_PRESSURE_PA
    assert config.rig["sample_rate_hz"] == SENSOR_RATE_HZ
    signature = inspect.signature(SimHardware).parameters
    assert signature["max_pressure_pa"].default == MAX_PRESSURE_PA
    assert signature["command_timeout_s"].default == COMMAND_TIMEOUT_S
    assert evaluate.DEFAULT_MAX_PRESSURE_PA == MAX_PRESSURE_PA
    assert evaluate.DEFAULT_MAX_SLEW_PA_PER_S == MAX_SLEW_PA_PER_S
    subcommands = next(
        a for a in build_parser()._actions if isinstance(a, argparse._SubParsersAction)
    )
    for command in ("train", "tune"):
        assert subcommands.choices[command].get_default("rate_hz") == SENSOR_RATE_HZ, command


# -- QoS: one set of numbers for rclpy and for the bags ---------------------------------------


def _rclpy_profile(spec: QosSpec) -> QoSProfile:
    return QoSProfile(
        history=HistoryPolicy.KEEP_LAST,
        depth=spec.depth,
        reliability=ReliabilityPolicy.RELIABLE if spec.reliable else ReliabilityPolicy.BEST_EFFORT,
        durability=(
            DurabilityPolicy.TRANSIENT_LOCAL if spec.transient_local else DurabilityPolicy.VOLATILE
        ),
    )


@pytest.mark.parametrize(
    ("profile", "spec"),
    [
        ("STREAM", contract.QOS_STREAM),
        ("KEEP_EVERY_SAMPLE", contract.QOS_KEEP_EVERY_SAMPLE),
        ("RECORD", contract.QOS_RECORD),
        ("TRAJECTORY", contract.QOS_TRAJECTORY),
        ("SENSOR", contract.QOS_SENSOR_DATA),
    ],
)
def test_the_rclpy_profiles_are_the_contract_s_specs(profile: str, spec: QosSpec) -> None:
    from catheter_ros import qos

    assert getattr(qos, profile) == _rclpy_profile(spec)


def test_the_stream_profiles_are_as_deep_as_the_contract_says() -> None:
    from catheter_ros import qos

    assert qos.STREAM_DEPTH == contract.STREAM_DEPTH == 500
    assert qos.STREAM.depth == qos.RECORD.depth == qos.KEEP_EVERY_SAMPLE.depth == 500


@pytest.mark.parametrize(
    ("offered", "spec"),
    [
        (metadata.STREAM_QOS, contract.QOS_STREAM),
        (metadata.LATCHED_QOS, contract.QOS_TRAJECTORY),
        (metadata.SENSOR_DATA_QOS, contract.QOS_SENSOR_DATA),
    ],
)
def test_a_bag_records_the_contract_s_qos(offered: metadata.QosProfile, spec: QosSpec) -> None:
    assert (offered.history, offered.depth, offered.reliability, offered.durability) == (
        "keep_last",
        spec.depth,
        "reliable" if spec.reliable else "best_effort",
        "transient_local" if spec.transient_local else "volatile",
    )
