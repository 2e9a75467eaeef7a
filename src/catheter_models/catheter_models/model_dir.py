"""Model directories (docs/interfaces.md, "Models on disk"): a manifest plus weight files.

The manifest (``manifest.json``) gives the kind, the input and output signals with units,
normalisation, training bags with their hashes, metrics, the software version and a sha256 of
every weight file. Loading re-hashes every file and refuses any mismatch, so a tampered or
half-copied model never drives a catheter. Nothing is loaded with pickle.
"""

from __future__ import annotations

import hashlib
import json
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path, PurePath
from typing import Any

from catheter_models import __version__
from catheter_models.errors import CatheterError

MANIFEST = "manifest.json"
FORMAT_VERSION = 1


class ModelDirError(CatheterError):
    """A model directory is missing, malformed, or fails its hash check."""


def sha256_file(path: Path) -> str:
    """Hex sha256 of a file, streamed (model and bag files can be large)."""
    digest = hashlib.sha256()
    with path.open("rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()


@dataclass(frozen=True)
class Manifest:
    """What a model directory says about itself."""

    kind: str
    inputs: Mapping[str, str]
    outputs: Mapping[str, str]
    files: Mapping[str, str]
    normalization: Mapping[str, Any] = field(default_factory=dict)
    training_bags: Mapping[str, str] = field(default_factory=dict)
    metrics: Mapping[str, Any] = field(default_factory=dict)
    software_version: str = __version__
    format_version: int = FORMAT_VERSION

    def to_json(self) -> str:
        """Stable, human-readable JSON, sealed with its own hash (``manifest_sha256``)."""
        return seal_manifest(
            {
                "format_version": self.format_version,
                "kind": self.kind,
                "inputs": dict(self.inputs),
                "outputs": dict(self.outputs),
                "normalization": dict(self.normalization),
                "training_bags": dict(self.training_bags),
                "metrics": dict(self.metrics),
                "software_version": self.software_version,
                "files": dict(self.files),
            }
        )


MANIFEST_HASH_KEY = "manifest_sha256"
"""The manifest's hash of itself: normalisation constants and the weight files' hashes live in
the manifest, so an edit to it must fail the check as an edited weight file does."""


def _manifest_digest(content: Mapping[str, Any]) -> str:
    """sha256 of the manifest without its own hash, as canonical JSON (sorted, compact)."""
    body = {k: v for k, v in content.items() if k != MANIFEST_HASH_KEY}
    canonical = json.dumps(body, sort_keys=True, separators=(",", ":"), allow_nan=False)
    return hashlib.sha256(canonical.encode()).hexdigest()


def seal_manifest(content: Mapping[str, Any]) -> str:
    """``content`` as indented JSON with its ``manifest_sha256``."""
    return json.dumps(
        {**content, MANIFEST_HASH_KEY: _manifest_digest(content)}, indent=2, sort_keys=True
    )


def bag_names(training_bags: Mapping[str, str]) -> dict[str, str]:
    """``training_bags`` keyed by bag name (the last part of a path), as manifests hold them.

    A path is the training machine's and means nothing where the model ships; the bag's name
    and hash find and prove it in any bags directory. Two different bags of one name are
    refused: the manifest could not tell them apart.
    """
    named: dict[str, str] = {}
    for key, sha in training_bags.items():
        name = PurePath(key).name or key
        if named.get(name, sha) != sha:
            raise ModelDirError(
                f"two training bags are named {name!r} with different sha256; rename one"
            )
        named[name] = sha
    return named


def write_model_dir(
    path: Path,
    kind: str,
    inputs: Mapping[str, str],
    outputs: Mapping[str, str],
    payload: Mapping[str, bytes],
    **extra: Any,
) -> Manifest:
    """Write weight files and a manifest that hashes them. Refuses to overwrite a model.

    Training bags are recorded by name (:func:`bag_names`), whatever the caller passed.
    """
    path = Path(path)
    if "training_bags" in extra:
        extra["training_bags"] = bag_names(extra["training_bags"])
    if (path / MANIFEST).exists():
        raise ModelDirError(f"{path} already holds a model; choose a new directory")
    path.mkdir(parents=True, exist_ok=True)
    hashes = {}
    for name, data in payload.items():
        if "/" in name or name in {MANIFEST, ""}:
            raise ModelDirError(f"invalid weight file name {name!r}")
        (path / name).write_bytes(data)
        hashes[name] = hashlib.sha256(data).hexdigest()
    manifest = Manifest(kind=kind, inputs=inputs, outputs=outputs, files=hashes, **extra)
    tmp = path / (MANIFEST + ".tmp")
    tmp.write_text(manifest.to_json() + "\n")
    tmp.replace(path / MANIFEST)  # the manifest appears last, and whole
    return manifest


def _check_seal(manifest_path: Path, raw: Mapping[str, Any]) -> None:
    sealed = raw.get(MANIFEST_HASH_KEY)
    if sealed is None:
        raise ModelDirError(
            f"{manifest_path} has no {MANIFEST_HASH_KEY}: it was edited, or written by a "
            "version that did not seal manifests; refusing to load it"
        )
    actual = _manifest_digest(raw)
    if sealed != actual:
        raise ModelDirError(
            f"{manifest_path} fails its own sha256 check ({MANIFEST_HASH_KEY} "
            f"{str(sealed)[:12]}..., content {actual[:12]}...): the manifest was modified or "
            "damaged; refusing to load it"
        )


def read_manifest(path: Path, expected_kind: str | None = None) -> Manifest:
    """A model directory's manifest, its seal checked; the weight files are not read.

    For what only the manifest answers (the kind, to pick the class that loads the whole
    directory): :func:`read_model_dir` reads and hash-checks the files once, then.

    Raises:
        ModelDirError: no manifest, a malformed or unsealed one, or the wrong kind.
    """
    path = Path(path)
    manifest_path = path / MANIFEST
    if not manifest_path.is_file():
        raise ModelDirError(f"{path} is not a model directory: no {MANIFEST}")
    try:
        raw = json.loads(manifest_path.read_text())
    except ValueError as exc:
        raise ModelDirError(f"{manifest_path} is malformed: {exc}") from None
    if not isinstance(raw, dict):
        raise ModelDirError(f"{manifest_path} is malformed: not a JSON object")
    _check_seal(manifest_path, raw)
    try:
        manifest = Manifest(
            kind=str(raw["kind"]),
            inputs=dict(raw["inputs"]),
            outputs=dict(raw["outputs"]),
            files=dict(raw["files"]),
            normalization=dict(raw.get("normalization", {})),
            training_bags=dict(raw.get("training_bags", {})),
            metrics=dict(raw.get("metrics", {})),
            software_version=str(raw.get("software_version", "")),
            format_version=int(raw.get("format_version", 0)),
        )
    except (ValueError, KeyError, TypeError) as exc:
        raise ModelDirError(f"{manifest_path} is malformed: {exc}") from None
    if manifest.format_version != FORMAT_VERSION:
        raise ModelDirError(
            f"{manifest_path} has format_version {manifest.format_version}; "
            f"this software reads {FORMAT_VERSION}"
        )
    if expected_kind is not None and manifest.kind != expected_kind:
        raise ModelDirError(f"{path} holds a {manifest.kind!r} model, expected {expected_kind!r}")
    return manifest


def read_model_dir(
    path: Path, expected_kind: str | None = None
) -> tuple[Manifest, dict[str, bytes]]:
    """Read and verify a model directory; returns the manifest and the verified file bytes.

    Raises:
        ModelDirError: no manifest, malformed manifest, wrong kind, a file missing, or a
            sha256 mismatch (the message names the file).
    """
    path = Path(path)
    manifest = read_manifest(path, expected_kind)
    payload = {}
    for name, expected in manifest.files.items():
        file_path = path / name
        if not file_path.is_file():
            raise ModelDirError(f"{path}: weight file {name!r} named in the manifest is missing")
        data = file_path.read_bytes()
        actual = hashlib.sha256(data).hexdigest()
        if actual != expected:
            raise ModelDirError(
                f"{path}: {name!r} fails its sha256 check (manifest {expected[:12]}..., "
                f"file {actual[:12]}...): the model was modified or damaged; refusing to load it"
            )
        payload[name] = data
    return manifest, payload
