"""The shipped Foxglove layout opens our bags as they are.

Every message path the layout plots (and every topic a panel reads) must name a topic of one of
the sample bags under ``bags/`` and a field path its recorded schema has, ending in a number
where a plot needs one; where the bag holds messages on the topic, the path is also evaluated
on a decoded message. Topics a bag cannot hold by design are listed in ``LIVE_ONLY`` and must
then be ones the live view sends, so the list cannot rot.
"""

from __future__ import annotations

import json
import re
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory

from catheter_control import live_view
from catheter_control.tip_tf import URDF_PACKAGE_URL
from catheter_models.contract import BEND_JOINT, qualify

REPO = Path(__file__).resolve().parents[2]
LAYOUT = REPO / "src/catheter_control/catheter_control/foxglove/catheter_layout.json"
BAGS = sorted((REPO / "bags").glob("*/*.mcap"))

LIVE_ONLY = {"/diagnostics": "the recorder does not record diagnostics (not science data)"}
MODIFIERS = {"@degrees"}
"""Foxglove math modifiers the layout may use, all number -> number."""
NUMERIC = {"float64", "float32", "int8", "int16", "int32", "int64", "uint8", "uint16", "uint32"}
_PRIMITIVES = NUMERIC | {"string", "bool", "byte", "char", "uint64"}


def _paths(layout: dict[str, Any]) -> Iterator[tuple[str, str, bool]]:
    """(panel, message path or topic, whether it must end in a number) of every panel."""
    for panel, config in layout["configById"].items():
        kind = panel.split("!")[0]
        if kind == "Plot":
            for series in config["paths"]:
                yield panel, series["value"], True
            if config.get("xAxisVal") == "custom":
                yield panel, config["xAxisPath"]["value"], True
        elif kind == "3D":
            for layer in config["layers"].values():
                if layer["layerId"] == "foxglove.Urdf":
                    yield panel, layer["jointStatesTopic"], False
        elif kind == "DiagnosticSummary":
            yield panel, config["topicToRender"], False
        else:
            raise AssertionError(f"{panel}: a panel kind this test does not check")


def _schemas() -> dict[str, tuple[str, str, list[Any]]]:
    """topic -> (schema name, ros2msg text, up to 2 decoded messages) over every sample bag."""
    out: dict[str, tuple[str, str, list[Any]]] = {}
    decoders = DecoderFactory()
    for bag in BAGS:
        with bag.open("rb") as f:
            reader = make_reader(f, decoder_factories=[decoders])
            summary = reader.get_summary()
            assert summary is not None and summary.statistics is not None
            for channel in summary.channels.values():
                schema = summary.schemas[channel.schema_id]
                msgs = out.setdefault(channel.topic, (schema.name, schema.data.decode(), []))[2]
                if not msgs and summary.statistics.channel_message_counts.get(channel.id):
                    for _, _, _, msg in reader.iter_decoded_messages(topics=[channel.topic]):
                        msgs.append(msg)
                        break
    return out


def _definitions(msgdef: str) -> dict[str, dict[str, str]]:
    """Type name -> {field: type} of a ros2msg schema text ("" names the main type)."""
    out: dict[str, dict[str, str]] = {}
    for i, part in enumerate(re.split(r"^=+\n", msgdef, flags=re.MULTILINE)):
        lines = [ln.split("#")[0].strip() for ln in part.strip().splitlines()]
        name = "" if i == 0 else lines.pop(0).removeprefix("MSG: ")
        fields = [ln.split() for ln in lines if ln]
        # "type name" is a field; "type NAME=value" is a constant.
        out[name] = {f[1]: f[0] for f in fields if "=" not in f[1]}
    return out


def _resolve_type(msgdef: str, path: list[str]) -> str:
    """The type a field path ends in, walking the schema (``name[3]`` indexes an array)."""
    definitions = _definitions(msgdef)
    current = ""
    for segment in path:
        name, index = re.fullmatch(r"(\w+)(?:\[(\d+)\])?", segment).groups()  # type: ignore[union-attr]
        fields = definitions.get(current)
        assert fields is not None, f"{current} is not a message type; cannot take .{name}"
        assert name in fields, f"field {name!r} not in {current or 'the message'}: {sorted(fields)}"
        current = fields[name]
        if index is not None:
            assert current.endswith("]"), f"{name} is not an array ({current})"
            current = current[: current.index("[")]
    return current


def _evaluate(msg: Any, path: list[str]) -> Any:
    value = msg
    for segment in path:
        name, index = re.fullmatch(r"(\w+)(?:\[(\d+)\])?", segment).groups()  # type: ignore[union-attr]
        value = getattr(value, name)
        if index is not None:
            value = value[int(index)]
    return value


def _split(path: str) -> tuple[str, list[str], list[str]]:
    """A Foxglove message path: topic, field segments, modifiers."""
    topic, _, rest = path.partition(".")
    parts = rest.split(".") if rest else []
    return topic, [p for p in parts if not p.startswith("@")], [p for p in parts if p[:1] == "@"]


@pytest.fixture(scope="module")
def layout() -> dict[str, Any]:
    return json.loads(LAYOUT.read_text())  # type: ignore[no-any-return]


@pytest.fixture(scope="module")
def recorded() -> dict[str, tuple[str, str, list[Any]]]:
    assert BAGS, "no sample bags under bags/"
    return _schemas()


def test_every_layout_path_resolves_in_a_sample_bag(
    layout: dict[str, Any], recorded: dict[str, tuple[str, str, list[Any]]]
) -> None:
    checked = 0
    for panel, path, numeric in _paths(layout):
        topic, fields, modifiers = _split(path)
        assert set(modifiers) <= MODIFIERS, f"{panel}: {path}: unknown modifier"
        if topic in LIVE_ONLY:
            continue
        assert topic in recorded, f"{panel}: {topic} is in no sample bag ({sorted(recorded)})"
        _name, msgdef, msgs = recorded[topic]
        end = _resolve_type(msgdef, fields)
        if numeric:
            assert end in NUMERIC, f"{panel}: {path} ends in {end}, not a number"
        for msg in msgs:
            value = _evaluate(msg, fields)
            if numeric:
                assert isinstance(value, int | float), f"{panel}: {path} gave {value!r}"
            if fields[:1] == ["position[0]"]:
                # JointState is parallel arrays: position[0] is the bend only if name[0] is.
                assert list(msg.name) == [BEND_JOINT], f"{topic}: joints {list(msg.name)}"
        checked += 1
    assert checked >= 6, checked


def test_live_only_topics_are_ones_the_live_view_sends(
    layout: dict[str, Any], recorded: dict[str, tuple[str, str, list[Any]]]
) -> None:
    sent = {qualify(spec) for spec in live_view.FORWARDED}
    for topic, why in LIVE_ONLY.items():
        assert topic not in recorded, f"{topic} is recorded now; drop it from LIVE_ONLY ({why})"
        assert topic in sent, f"{topic} is neither in a bag nor sent live"
    # Everything a panel reads live is something the live view forwards.
    for panel, path, _ in _paths(layout):
        assert _split(path)[0] in sent, f"{panel}: the live view does not send {path}"


def test_the_3d_panel_loads_the_model_the_live_view_serves(layout: dict[str, Any]) -> None:
    urdf_layers = [
        layer
        for panel, config in layout["configById"].items()
        if panel.startswith("3D!")
        for layer in config["layers"].values()
        if layer["layerId"] == "foxglove.Urdf"
    ]
    assert [(lay["sourceType"], lay["url"]) for lay in urdf_layers] == [("url", URDF_PACKAGE_URL)]
    assert live_view.LiveView._asset(URDF_PACKAGE_URL) is not None
    assert live_view.LiveView._asset("package://catheter_control/../../etc/passwd") is None
