"""The launch files stay in step with ``bringup``: same nodes, same parameters, all activated.

The ROS ``launch`` package has no wheel here, so ``launch`` and ``launch_ros`` are replaced by
small fakes that record what each action is given; launch arguments resolve to their
defaults. A parameter the launch file passes is compared with what the node runs under
``bringup``: the spec's value, or else the node's own default (read from the node, built
in-process), so a launch default that differs from the node's shows up.
"""

from __future__ import annotations

import importlib.metadata
import importlib.util
import sys
import types
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import pytest
import yaml

import catheter_control
from catheter_control.bringup import driver_specs, sim_graph_specs
from catheter_control.graph_description import LIFECYCLE_MODULES, SIM_COMPENSATOR_PARAMS
from catheter_control.process_graph import NodeSpec

LAUNCH_DIR = Path(__file__).resolve().parents[2] / "src/catheter_control/launch"
CONFIGURE, ACTIVATE = 1, 3  # lifecycle_msgs/msg/Transition ids
SHARED = "catheter_control.launch_common"


# -- fakes of launch and launch_ros -----------------------------------------------------------


@dataclass
class Launched:
    """What a Node or LifecycleNode action was given."""

    kind: str
    kwargs: dict[str, Any]


@dataclass
class Fakes:
    """Everything the launch file made, in order."""

    arguments: dict[str, Any] = field(default_factory=dict)
    nodes: list[Launched] = field(default_factory=list)
    configure: list[Launched] = field(default_factory=list)
    activate_on_inactive: list[Launched] = field(default_factory=list)


def _fake_modules(fakes: Fakes) -> dict[str, types.ModuleType]:
    class Substitution:
        def resolve(self) -> str:
            raise NotImplementedError

    class LaunchConfiguration(Substitution):
        def __init__(self, name: str) -> None:
            self.name = name

        def resolve(self) -> str:
            return resolve(fakes.arguments[self.name])

    class PathJoinSubstitution(Substitution):
        def __init__(self, parts: list[Any]) -> None:
            self.parts = parts

        def resolve(self) -> str:
            return "/".join(resolve(p) for p in self.parts)

    class FindPackageShare(Substitution):
        def __init__(self, package: str) -> None:
            self.package = package

        def resolve(self) -> str:
            return f"<share>/{self.package}"

    def resolve(value: Any) -> str:
        if isinstance(value, Substitution):
            return value.resolve()
        if isinstance(value, list):
            return "".join(resolve(v) for v in value)
        return str(value)

    class ParameterValue:
        def __init__(self, value: Any, value_type: type | None = None) -> None:
            self.value, self.value_type = value, value_type

        def resolve(self) -> Any:
            text = resolve(self.value)
            if self.value_type is str:
                return text
            # As launch_ros does for typed values: YAML rules, then checked against the type.
            value = yaml.safe_load(text)
            if self.value_type is float and isinstance(value, int):
                value = float(value)
            assert self.value_type is None or isinstance(value, self.value_type), (text, value)
            return value

    class DeclareLaunchArgument:
        def __init__(self, name: str, default_value: Any = None, **_kwargs: Any) -> None:
            fakes.arguments[name] = default_value

    class LaunchDescription:
        def __init__(self, entities: list[Any]) -> None:
            self.entities = entities

    class Node:
        def __init__(self, **kwargs: Any) -> None:
            fakes.nodes.append(Launched("Node", kwargs))

    class LifecycleNode:
        def __init__(self, **kwargs: Any) -> None:
            assert "name" in kwargs and "namespace" in kwargs, "LifecycleNode needs both"
            self.launched = Launched("LifecycleNode", kwargs)
            fakes.nodes.append(self.launched)

    def matches_action(action: Any) -> Any:
        return ("matches", action)

    class ChangeState:
        def __init__(self, *, lifecycle_node_matcher: Any, transition_id: int) -> None:
            self.node = lifecycle_node_matcher[1]
            self.transition_id = transition_id

    class EmitEvent:
        def __init__(self, *, event: Any) -> None:
            self.event = event
            if isinstance(event, ChangeState) and event.transition_id == CONFIGURE:
                fakes.configure.append(event.node.launched)

    class OnStateTransition:
        def __init__(
            self,
            *,
            target_lifecycle_node: Any,
            goal_state: str,
            entities: list[Any],
            start_state: str | None = None,
        ) -> None:
            for entity in entities:
                event = entity.event
                if (
                    goal_state == "inactive"
                    and start_state == "configuring"
                    and event.transition_id == ACTIVATE
                    and event.node is target_lifecycle_node
                ):
                    fakes.activate_on_inactive.append(target_lifecycle_node.launched)

    class RegisterEventHandler:
        def __init__(self, handler: Any) -> None:
            self.handler = handler

    class IfCondition:
        def __init__(self, condition: Any) -> None:
            self.condition = condition

    class Transition:
        TRANSITION_CONFIGURE = CONFIGURE
        TRANSITION_ACTIVATE = ACTIVATE

    contents: dict[str, dict[str, Any]] = {
        "launch": {"LaunchDescription": LaunchDescription},
        "launch.actions": {
            "DeclareLaunchArgument": DeclareLaunchArgument,
            "EmitEvent": EmitEvent,
            "RegisterEventHandler": RegisterEventHandler,
        },
        "launch.conditions": {"IfCondition": IfCondition},
        "launch.events": {"matches_action": matches_action},
        "launch.substitutions": {
            "LaunchConfiguration": LaunchConfiguration,
            "PathJoinSubstitution": PathJoinSubstitution,
        },
        "launch_ros": {},
        "launch_ros.actions": {"Node": Node, "LifecycleNode": LifecycleNode},
        "launch_ros.event_handlers": {"OnStateTransition": OnStateTransition},
        "launch_ros.events": {},
        "launch_ros.events.lifecycle": {"ChangeState": ChangeState},
        "launch_ros.parameter_descriptions": {"ParameterValue": ParameterValue},
        "launch_ros.substitutions": {"FindPackageShare": FindPackageShare},
        "lifecycle_msgs.msg": {"Transition": Transition},
    }
    modules = {}
    for name, attrs in contents.items():
        module = types.ModuleType(name)
        module.__dict__.update(attrs)
        modules[name] = module
    modules["resolve"] = types.SimpleNamespace(resolve=resolve)  # type: ignore[assignment]
    return modules


@pytest.fixture
def run_launch_file(monkeypatch: pytest.MonkeyPatch) -> Iterator[Any]:
    """Call a launch file's generate_launch_description() against the fakes."""

    def run(filename: str) -> tuple[Fakes, Any]:
        fakes = Fakes()
        modules = _fake_modules(fakes)
        resolve = modules.pop("resolve").resolve  # type: ignore[attr-defined]
        for name, module in modules.items():
            monkeypatch.setitem(sys.modules, name, module)
        # The launch files share catheter_control.launch_common, which imports launch at its
        # top: import it afresh against these fakes, and take it away again afterwards
        # (monkeypatch puts back what was there before: nothing, where launch is not installed).
        monkeypatch.setitem(sys.modules, SHARED, None)
        monkeypatch.delitem(sys.modules, SHARED)
        monkeypatch.setattr(catheter_control, "launch_common", None, raising=False)
        spec = importlib.util.spec_from_file_location(filename, LAUNCH_DIR / filename)
        assert spec is not None and spec.loader is not None
        module = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(module)
        module.generate_launch_description()
        return fakes, resolve

    yield run


# -- what the nodes run with --------------------------------------------------------------------


def _module_of(package: str, executable: str) -> str:
    """The module an installed ``ros2 run <package> <executable>`` runs (its console script)."""
    (entry,) = [
        e
        for e in importlib.metadata.entry_points(group="console_scripts")
        if e.name == executable and e.value.startswith(f"{package}.")
    ]
    return entry.value.split(":", 1)[0]


def _launched_params(node: Launched, resolve: Any) -> dict[str, Any]:
    params: dict[str, Any] = {}
    for item in node.kwargs.get("parameters", []):
        if isinstance(item, dict):
            params.update({k: v.resolve() if hasattr(v, "resolve") else v for k, v in item.items()})
    return params


@pytest.fixture(scope="module")
def node_defaults() -> Iterator[dict[str, dict[str, Any]]]:
    """Each lifecycle node's declared parameter values with no override (built in-process).

    Lifecycle nodes only declare at construction (no model, no device, no loop until
    configure), so this is cheap.
    """
    import rclpy
    from rclpy.context import Context

    context = Context()
    rclpy.init(args=["defaults"], context=context)
    defaults: dict[str, dict[str, Any]] = {}
    try:
        for module_name in sorted(LIFECYCLE_MODULES):
            module = importlib.import_module(module_name)
            (cls,) = [
                obj
                for name, obj in vars(module).items()
                if name.endswith("Node") and getattr(obj, "__module__", "") == module_name
            ]
            # The node classes take no context argument: build them on this one.
            original = rclpy.node.Node.__init__

            def on_context(self: Any, *args: Any, _orig: Any = original, **kwargs: Any) -> None:
                kwargs.setdefault("context", context)
                _orig(self, *args, **kwargs)

            with pytest.MonkeyPatch.context() as mp:
                mp.setattr(rclpy.node.Node, "__init__", on_context)
                node = cls()
            try:
                defaults[module_name] = {
                    name: param.value for name, param in node._parameters.items()
                }
            finally:
                node.destroy_node()
    finally:
        rclpy.shutdown(context=context)
    yield defaults


def _check_same(
    fakes: Fakes,
    resolve: Any,
    specs: list[NodeSpec],
    defaults: dict[str, dict[str, Any]],
    per_run: set[str],
) -> None:
    launched = {n.kwargs["name"]: n for n in fakes.nodes}
    assert sorted(launched) == sorted(s.name for s in specs)
    for spec in specs:
        node = launched[spec.name]
        assert _module_of(node.kwargs["package"], node.kwargs["executable"]) == spec.module
        assert (node.kind == "LifecycleNode") == spec.lifecycle, spec.name
        params = _launched_params(node, resolve)
        own_defaults = defaults.get(spec.module, {})
        for key in spec.params.keys() - per_run:
            assert key in params, f"{spec.name}: bringup sets {key}, the launch file does not"
        for key, value in params.items():
            if key in per_run:
                continue
            if spec.name == "compensator" and key == "compensator" and value == "":
                # '' is the node's own choice (model_dir's kind, else its default), which is
                # what bringup gives by leaving the parameter out.
                assert key not in spec.params, f"bringup sets {key}, the launch file leaves it"
                continue
            expected = spec.params.get(key, own_defaults.get(key, "<not declared>"))
            assert value == expected, f"{spec.name}.{key}: launch {value!r}, bringup {expected!r}"


def test_sim_launch_starts_what_bringup_starts(
    run_launch_file: Any, node_defaults: dict[str, dict[str, Any]]
) -> None:
    fakes, resolve = run_launch_file("sim.launch.py")
    specs = sim_graph_specs(
        Path("bag"),
        {"source": "x"},
        compensator_params=dict(SIM_COMPENSATOR_PARAMS),
        with_tf=True,
    )
    # The bag's path and its metadata name the run: they differ by design.
    _check_same(fakes, resolve, specs, node_defaults, per_run={"bag_path", "custom_data"})


def test_rig_launch_starts_the_drivers_bringup_points_at_devices(
    run_launch_file: Any, node_defaults: dict[str, dict[str, Any]]
) -> None:
    fakes, resolve = run_launch_file("rig.launch.py")
    recorder, _sim, compensator, tip_tf = sim_graph_specs(
        Path("bag"), {"source": "x"}, with_tf=True
    )
    ports = {
        "keller_serial": {"port": "/dev/a"},
        "dac_serial": {"port": "/dev/b"},
        "adc_serial": {"port": "/dev/c"},
    }
    specs = [recorder, *driver_specs(ports, Path("cal.json")), compensator, tip_tf]
    # The drivers' devices come from the shipped parameter files on the rig, from the
    # emulator's ports under bringup; the compensator runs with its own defaults on both.
    device_keys = {k for s in specs for k in s.params if s.name in {"valve_driver", "laser_angle"}}
    _check_same(
        fakes,
        resolve,
        specs,
        node_defaults,
        per_run={"bag_path", "custom_data", *device_keys},
    )
    files = {
        n.kwargs["name"]: [p for p in n.kwargs["parameters"] if not isinstance(p, dict)]
        for n in fakes.nodes
        if n.kwargs["name"] in {"valve_driver", "laser_angle"}
    }
    assert all(files.values()), f"a driver without its parameter file: {files}"


@pytest.mark.parametrize("filename", ["sim.launch.py", "rig.launch.py"])
def test_every_lifecycle_node_is_configured_then_activated(
    run_launch_file: Any, filename: str
) -> None:
    fakes, _resolve = run_launch_file(filename)
    lifecycle = [n for n in fakes.nodes if n.kind == "LifecycleNode"]
    assert lifecycle
    assert [id(n) for n in fakes.configure] == [id(n) for n in lifecycle]
    assert {id(n) for n in fakes.activate_on_inactive} == {id(n) for n in lifecycle}


def test_the_graph_description_names_what_is_installed() -> None:
    """Each node of the description is its package's console script for its module, and is a
    lifecycle node exactly when the description says so: the launch files run the executable
    and ``bringup`` the module, so a mismatch would start two different graphs."""
    from rclpy.lifecycle import LifecycleNode

    from catheter_control.graph_description import GRAPH

    scripts = {
        (e.dist.name if e.dist else "", e.name): e.value
        for e in importlib.metadata.entry_points(group="console_scripts")
    }
    for node in GRAPH:
        assert scripts.get((node.package, node.executable)) == f"{node.module}:main", node
        module = importlib.import_module(node.module)
        classes = [
            obj
            for obj in vars(module).values()
            if isinstance(obj, type) and getattr(obj, "__module__", "") == node.module
        ]
        is_lifecycle = any(issubclass(cls, LifecycleNode) for cls in classes)
        assert is_lifecycle == node.lifecycle, (node.name, classes)
