"""Training data for the models: recordings from bags (playback for training) or the plant.

``recording_from_bag`` is the one way a bag becomes training data: it loads only the two
streams a model needs, refuses a bag that lacks them (naming the topic), resamples them on a
uniform grid, and hashes the bag so a model's manifest records exactly what it learned from.
``simulate_recordings`` runs thesis signal presets through the offline plant, for benchmarks
and tests that need many signals fast; it yields the same ``Recording`` a bag does.
``locate_training_bags`` goes the other way: from a manifest's ``training_bags`` (bag name ->
hash) to the bags themselves in a bags directory, each checked against its hash.
"""

from __future__ import annotations

import hashlib
import warnings
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import replace
from pathlib import Path

import numpy as np

from catheter_models.bag.metadata import locate_bag
from catheter_models.bag.plausible import PlausibilityWarning
from catheter_models.bag.reader import load_bag
from catheter_models.contract import PRESSURE_COMMAND, SENSOR_RATE_HZ, TIP_ANGLE
from catheter_models.errors import BagError, MissingTopicError
from catheter_models.gaps import BagGapWarning
from catheter_models.models.base import Recording
from catheter_models.plant import Plant, PlantConfig
from catheter_models.signals import SignalSpec, get_preset


def bag_sha256(path: Path | str) -> str:
    """One sha256 over a bag's storage files, in playback order (metadata excluded)."""
    layout = locate_bag(path)
    digest = hashlib.sha256()
    for f in layout.storage_files:
        with f.open("rb") as fh:
            for block in iter(lambda: fh.read(1 << 20), b""):
                digest.update(block)
    return digest.hexdigest()


def recording_from_bag(
    path: Path | str, rate_hz: float = SENSOR_RATE_HZ, *, accept_implausible: bool = False
) -> Recording:
    """Load the valve command and the measured angle of a bag on a uniform ``rate_hz`` grid.

    The bag's data must be plausible (``bag.plausible``): a refusing finding refuses the bag
    unless ``accept_implausible`` (a person going on knowingly).

    Warns:
        BagGapWarning: A stream lacks samples (one warning per stream, naming the gaps).
        PlausibilityWarning: One per plausibility finding on a bag that is used (warnings,
            and accepted refusals).

    Raises:
        MissingTopicError: The bag lacks ``pressure/command`` or ``tip/angle``: it does not fit
            the models' signals (the message names the topic and lists the bag's).
        TruncatedBagError: The recorder was killed; the message says how to repair the bag.
        ImplausibleBagError: The data fails the plausibility check (each finding named).
        BagError: Any other reason the bag cannot be read as the contract says.
    """
    path = Path(path)
    try:
        data = load_bag(
            path,
            topics=[PRESSURE_COMMAND.name, TIP_ANGLE.name, "pressure/measured"],
            require_plausible=not accept_implausible,
        )
    except MissingTopicError as exc:
        raise MissingTopicError(
            f"{path} does not fit the models' signals (input {PRESSURE_COMMAND.name}, "
            f"output {TIP_ANGLE.name}): {exc}"
        ) from None
    for finding in data.plausibility.findings:
        warnings.warn(
            PlausibilityWarning(path, finding, accepted=finding.severity == "refuse"),
            stacklevel=2,
        )
    # The uniform grid is not cut at a gap: it holds the command from before it (as the valve
    # held it) and interpolates a measurement across it. Say so, naming where, so nobody
    # trains on made-up samples without knowing.
    for line in data.gap_report():
        fill = (
            "holds the last command over it"
            if line.startswith(PRESSURE_COMMAND.name + " ")
            else "interpolates across it"
        )
        warnings.warn(
            BagGapWarning(f"{path}: {line}; the {rate_hz:g} Hz grid {fill}"), stacklevel=2
        )
    aligned = data.aligned(rate_hz=rate_hz)
    if len(aligned) < 2:
        raise BagError(f"{path}: the model streams overlap for {len(aligned)} sample(s) only")
    return Recording(
        name=path.name,
        rate_hz=rate_hz,
        pressure_pa=np.asarray(aligned.pressure_command_pa),
        angle_rad=np.asarray(aligned.angle_rad),
        source=str(path),
        sha256=bag_sha256(path),
        measurement_age_s=data.tip_angle.arrival_age_s,
    )


def locate_training_bags(training_bags: Mapping[str, str], bags_dir: Path | str) -> dict[str, Path]:
    """Find each bag a model was trained on, by name, under ``bags_dir``; check its hash.

    A manifest names its training bags by bag name (a directory or ``.mcap`` file name) and
    sha256, never by path, so the same manifest resolves on any machine that holds the bags.
    A bag is looked for directly in ``bags_dir`` first, then anywhere below it. Entries
    without a hash (simulated recordings) are skipped.

    Args:
        training_bags: A manifest's ``training_bags``: bag name -> sha256 (:func:`bag_sha256`).
        bags_dir: Directory that holds the bags.

    Returns:
        Bag name -> its path, for every entry with a hash.

    Raises:
        BagError: A bag is not found, found more than once below ``bags_dir``, or fails its
            hash check (the message names it).
    """
    root = Path(bags_dir)
    found: dict[str, Path] = {}
    for name, expected in training_bags.items():
        if not expected:
            continue
        if "/" in name or "\\" in name:
            raise BagError(f"training bag {name!r} is a path, not a bag name")
        path = root / name
        if not path.exists():
            matches = sorted(root.rglob(name))
            if len(matches) != 1:
                where = "not found" if not matches else f"found {len(matches)} times"
                raise BagError(f"training bag {name!r} {where} under {root}")
            path = matches[0]
        actual = bag_sha256(path)
        if actual != expected:
            raise BagError(
                f"training bag {path} fails its sha256 check (manifest {expected[:12]}..., "
                f"bag {actual[:12]}...): it is not the bag the model was trained on"
            )
        found[name] = path
    return found


def recordings_from_bags(
    paths: Iterable[Path | str],
    rate_hz: float = SENSOR_RATE_HZ,
    *,
    accept_implausible: bool = False,
) -> list[Recording]:
    """:func:`recording_from_bag` for each path."""
    return [recording_from_bag(p, rate_hz, accept_implausible=accept_implausible) for p in paths]


def simulate_recording(
    spec: SignalSpec | str, config: PlantConfig | None = None, *, true_angle: bool = False
) -> Recording:
    """Run one pressure preset through the offline plant, from rest.

    Args:
        spec: A pressure signal preset (or its name).
        config: The plant; default: the thesis rig with seed 0.
        true_angle: Return the noise-free bend instead of the laser's (for identity checks).
    """
    spec = get_preset(spec) if isinstance(spec, str) else spec
    if spec.kind != "pressure":
        raise BagError(f"{spec.name!r} is an angle trajectory; recordings are driven by pressure")
    config = config or PlantConfig.thesis_rig()
    rate_hz = float(config.rig["sample_rate_hz"])
    signal = spec.generate(rate_hz)
    out = Plant(config).simulate(signal.values_si)
    angle = out.true_angle_rad if true_angle else out.angle_rad
    return Recording(
        name=spec.name,
        rate_hz=rate_hz,
        pressure_pa=np.asarray(out.pressure_command_pa),
        angle_rad=np.asarray(angle),
        source=f"simulated:{spec.name}",
    )


def simulate_recordings(
    specs: Sequence[SignalSpec | str], config: PlantConfig | None = None, *, seed0: int = 0
) -> list[Recording]:
    """:func:`simulate_recording` for each preset; each run gets its own noise seed."""
    base = config or PlantConfig.thesis_rig()
    out = []
    for i, spec in enumerate(specs):
        out.append(simulate_recording(spec, replace(base, seed=base.seed + seed0 + i)))
    return out
