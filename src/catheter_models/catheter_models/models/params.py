"""Named, range-checked parameter sets of the analytic models (Tables 5.1, 9.1) and their file.

One implementation of what every parameter table needs: each value checked against its
physical range when the set is built (the message names the parameter, the range and why),
round trips to a vector (for the optimiser) and to a mapping that refuse missing or unknown
names, and the one JSON file a model directory keeps them in (:class:`ParamsFile`: format tag,
values, units, structure). The DRDPI, the GPI and the IDRDPI all save and load through it.
"""

from __future__ import annotations

import json
import math
from collections.abc import Mapping
from dataclasses import dataclass, fields
from typing import TYPE_CHECKING, Any, ClassVar, Generic, TypeVar

import numpy as np
import numpy.typing as npt

from catheter_models.errors import ParameterError
from catheter_models.models.base import ModelError

if TYPE_CHECKING:
    from typing import Self  # 3.11+; annotations only, so 3.10 imports the module

FloatArray = npt.NDArray[np.float64]

Validity = Mapping[str, tuple[float, float, bool, str]]
"""name -> (low, high, low bound open?, why the range holds)."""


@dataclass(frozen=True)
class ParameterSet:
    """Base of a frozen dataclass of float parameters; subclasses declare the fields.

    Subclasses set ``label`` (how messages name the model, e.g. ``"DRDPI"``), ``table`` (where
    the order comes from, e.g. ``"Table 5.1"``) and ``validity``.
    """

    label: ClassVar[str]
    table: ClassVar[str]
    validity: ClassVar[Validity]

    @classmethod
    def names(cls) -> tuple[str, ...]:
        """Parameter names in the table's order."""
        return tuple(f.name for f in fields(cls))

    def __post_init__(self) -> None:
        for name in self.names():
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, (int, float, np.floating)):
                raise ParameterError(f"{self.label} parameter {name} = {value!r} is not a number")
            value = float(value)
            low, high, open_low, why = self.validity[name]
            low_ok = value > low if open_low else value >= low
            if not (math.isfinite(value) and low_ok and value <= high):
                bracket = "(" if open_low else "["
                raise ParameterError(
                    f"{self.label} parameter {name} = {value!r} is outside "
                    f"{bracket}{low:g}, {high:g}]: {why}"
                )
            object.__setattr__(self, name, value)

    def as_array(self) -> FloatArray:
        """The parameters as a vector in the table's order."""
        return np.array([getattr(self, n) for n in self.names()], dtype=np.float64)

    @classmethod
    def from_array(cls, theta: npt.ArrayLike) -> Self:
        """From a vector in the table's order (validated)."""
        values = np.asarray(theta, dtype=np.float64).ravel()
        names = cls.names()
        if values.size != len(names):
            raise ParameterError(
                f"a {cls.label} needs {len(names)} parameters {list(names)}, got {values.size}"
            )
        return cls(*(float(v) for v in values))

    def to_dict(self) -> dict[str, float]:
        """``{name: value}`` in the table's order."""
        return {n: float(getattr(self, n)) for n in self.names()}

    @classmethod
    def from_dict(cls, raw: Mapping[str, Any]) -> Self:
        """From ``{name: value}``; every name required, no other accepted."""
        names = cls.names()
        unknown = sorted(set(raw) - set(names))
        missing = [n for n in names if n not in raw]
        if unknown or missing:
            raise ParameterError(
                f"{cls.label} parameters: unknown {unknown}, missing {missing}; "
                f"expected exactly {list(names)}"
            )
        return cls(**{n: raw[n] for n in names})


P = TypeVar("P", bound=ParameterSet)


@dataclass(frozen=True)
class ParamsFile(Generic[P]):
    """The JSON file of a model's parameter set: ``format``, ``params``, ``units``, ``structure``.

    Attributes:
        name: File name in the model directory (e.g. ``"drdpi_params.json"``).
        format: Format tag written into the file and required when reading it.
        params_type: The parameter set the file holds.
    """

    name: str
    format: str
    params_type: type[P]

    def dump(self, params: P, units: Mapping[str, str], structure: Mapping[str, Any]) -> bytes:
        """The file's bytes: values, units and structure, as indented JSON."""
        doc = {
            "format": self.format,
            "params": params.to_dict(),
            "units": dict(units),
            "structure": dict(structure),
        }
        return (json.dumps(doc, indent=2) + "\n").encode()

    def read(self, payload: Mapping[str, bytes], kind: str) -> tuple[P, dict[str, Any]]:
        """Parameters and structure from a verified payload; ModelError if missing or malformed."""
        raw_bytes = payload.get(self.name)
        if raw_bytes is None:
            raise ModelError(f"{kind} model directory lacks {self.name}")
        try:
            doc = json.loads(raw_bytes)
            if doc.get("format") != self.format:
                raise ModelError(
                    f"{self.name} has format {doc.get('format')!r}, expected {self.format!r}"
                )
            params = self.params_type.from_dict(doc["params"])
            structure = dict(doc["structure"])
        except (ValueError, KeyError, TypeError, AttributeError) as exc:
            raise ModelError(f"{kind}: {self.name} is malformed: {exc}") from None
        return params, structure
