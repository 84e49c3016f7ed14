"""Typed access to a parsed TOML table that collects errors instead of raising.

Every accessor returns ``None`` when the value is unusable and records one message naming the
file, the key path, the value with its unit and the rule; the loader builds the model only when
no message was recorded, so a half-built model never escapes.
"""

from __future__ import annotations

import difflib
import math
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from typing import Any, TypeVar

import numpy as np

from cdprctl.core.angles import meant_degrees
from cdprctl.core.rotation import FloatArray

_MISSING = object()


def format_value(value: Any) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, float):
        return f"{value:g}"
    if isinstance(value, list | tuple):
        return "[" + ", ".join(format_value(v) for v in value) + "]"
    if isinstance(value, np.ndarray):
        return format_value(value.tolist())
    if isinstance(value, str):
        return repr(value)
    if isinstance(value, dict):
        return "{...}"
    return str(value)


def _is_number(value: Any) -> bool:
    return isinstance(value, int | float) and not isinstance(value, bool)


class TableReader:
    """Reads values from nested TOML tables, appending errors to ``errors``."""

    def __init__(self, file: str):
        self.file = file
        self.errors: list[str] = []

    # -- reporting --------------------------------------------------------------------------
    def error(self, path: str, value: Any, unit: str, rule: str) -> None:
        shown = format_value(value)
        unit_part = f" {unit}" if unit and _is_number(value) else ""
        self.errors.append(f"{self.file}: {path} = {shown}{unit_part} {rule}")

    def error_missing(self, path: str, unit: str, what: str) -> None:
        unit_part = f" (unit: {unit})" if unit else ""
        self.errors.append(f"{self.file}: {path} is missing: required, {what}{unit_part}")

    def check_keys(self, table: dict[str, Any], allowed: Iterable[str], path: str) -> None:
        allowed = list(allowed)
        for key in table:
            if key not in allowed:
                where = f"{path}.{key}" if path else key
                near = difflib.get_close_matches(key, allowed, n=1)
                hint = f"did you mean {near[0]}? " if near else ""
                self.errors.append(
                    f"{self.file}: {where} is not a known key ({hint}allowed here: "
                    f"{', '.join(sorted(allowed))})"
                )

    def section(
        self, data: dict[str, Any], key: str, allowed: Iterable[str], required: bool = False
    ) -> dict[str, Any] | None:
        """The top-level table ``key`` with its keys checked against ``allowed``; None where
        it is absent (reported when ``required``) or no table (reported)."""
        t = self.table(data, key, "", required=required)
        if t is not None:
            self.check_keys(t, allowed, key)
        return t

    # -- accessors --------------------------------------------------------------------------
    def _given(self, parent: dict[str, Any], key: str, path: str, unit: str, what: str,
               required: bool) -> tuple[str, Any]:  # fmt: skip
        """(the key's full path, its value: ``_MISSING`` where absent, reported as missing
        ``what`` when ``required``)."""
        full = f"{path}.{key}" if path else key
        value = parent.get(key, _MISSING)
        if value is _MISSING and required:
            self.error_missing(full, unit, what)
        return full, value

    def _of_kind(self, parent: dict[str, Any], key: str, path: str, what: str, rule: str,
                 required: bool, default: Any, ok: Callable[[Any], bool]) -> Any:  # fmt: skip
        """A unitless value that is ``what`` when ``ok``: ``default`` where absent (reported
        when ``required``), None after reporting ``rule`` where it is not."""
        full, value = self._given(parent, key, path, "", what, required)
        if value is _MISSING:
            return default
        if not ok(value):
            self.error(full, value, "", rule)
            return None
        return value

    def table(
        self, parent: dict[str, Any], key: str, path: str, *, required: bool = True
    ) -> dict[str, Any] | None:
        return self._of_kind(parent, key, path, "a table", "must be a table", required, None,
                             lambda v: isinstance(v, dict))  # fmt: skip

    def string(
        self,
        parent: dict[str, Any],
        key: str,
        path: str,
        *,
        required: bool = True,
        default: str | None = None,
    ) -> str | None:
        return self._of_kind(parent, key, path, "a string", "must be a non-empty string",
                             required, default,
                             lambda v: isinstance(v, str) and bool(v.strip()))  # fmt: skip

    def number(
        self,
        parent: dict[str, Any],
        key: str,
        path: str,
        unit: str,
        *,
        required: bool = True,
        default: float | None = None,
        minimum: float | None = None,
        positive: bool = False,
        maximum: float | None = None,
        integer: bool = False,
    ) -> float | None:
        what = "an integer" if integer else "a number"
        full, value = self._given(parent, key, path, unit, what, required)
        if value is _MISSING:
            return default
        if not _is_number(value):
            self.error(full, value, unit, "must be a number" + (f" in {unit}" if unit else ""))
            return None
        if integer and not isinstance(value, int):
            self.error(full, value, unit, "must be an integer")
            return None
        x = float(value)
        if not math.isfinite(x):
            self.error(full, value, unit, "must be finite")
            return None
        if positive and x <= 0.0:
            self.error(full, value, unit, "must be > 0")
            return None
        if minimum is not None and x < minimum:
            self.error(full, value, unit, f"must be >= {minimum:g}")
            return None
        if maximum is not None and x > maximum:
            hint = f" rad ({meant_degrees(f'{x:g}', x)})" if unit == "rad" and x > math.pi else ""
            self.error(full, value, unit, f"must be <= {maximum:g}{hint}")
            return None
        return x

    def vector(
        self,
        parent: dict[str, Any],
        key: str,
        path: str,
        unit: str,
        *,
        length: int = 3,
        required: bool = True,
        default: FloatArray | None = None,
    ) -> FloatArray | None:
        full, value = self._given(parent, key, path, unit, f"a list of {length} numbers", required)
        if value is _MISSING:
            return default
        if not isinstance(value, list) or len(value) != length:
            self.error(full, value, unit, f"must be a list of {length} numbers ({unit})")
            return None
        if not all(_is_number(v) for v in value):
            self.error(full, value, unit, f"must contain only numbers ({unit})")
            return None
        arr = np.array(value, dtype=np.float64)
        if not np.all(np.isfinite(arr)):
            self.error(full, value, unit, "must contain only finite numbers")
            return None
        return arr

    def rpy(self, parent: dict[str, Any], key: str, path: str) -> FloatArray | None:
        """Roll, pitch, yaw (rad; default zeros), each within ±π: a value beyond it is taken
        for degrees typed as radians and refused with what it likely meant."""
        rpy = self.vector(parent, key, path, "rad", required=False, default=np.zeros(3))
        if rpy is not None and (far := [a for a in rpy if abs(a) > math.pi]):
            self.error(f"{path}.{key}", rpy.tolist(), "rad", "must be within ±pi rad each ("
                       + meant_degrees(f"{far[0]:g}", float(far[0])) + ")")  # fmt: skip
            return None
        return rpy

    def matrix3(self, parent: dict[str, Any], key: str, path: str, unit: str) -> FloatArray | None:
        """A 3×3 matrix given as 3 rows, or its diagonal as 3 numbers."""
        what = "3 numbers (diagonal) or 3 rows of 3 numbers"
        full, value = self._given(parent, key, path, unit, what, True)
        if value is _MISSING:
            return None
        if isinstance(value, list) and len(value) == 3 and all(_is_number(v) for v in value):
            arr = np.diag(np.array(value, dtype=np.float64))
        elif (
            isinstance(value, list)
            and len(value) == 3
            and all(isinstance(r, list) and len(r) == 3 for r in value)
            and all(_is_number(v) for r in value for v in r)
        ):
            arr = np.array(value, dtype=np.float64)
        else:
            self.error(full, value, unit, "must be 3 numbers (diagonal) or 3 rows of 3 numbers")
            return None
        if not np.all(np.isfinite(arr)):
            self.error(full, value, unit, "must contain only finite numbers")
            return None
        return arr


# -- declarative fields ---------------------------------------------------------------------
# A section's plain keys as data: ``TableReader.fields`` reads each with the accessor its kind
# names, its rules and its default (the config's own, from ``defaults``), and puts what it
# read into ``into`` under the config's field name, so a section's reader keeps only what
# relates one key to another.


@dataclass(frozen=True)
class Number:
    """A number in ``unit``, with ``TableReader.number``'s rules; an integer is kept as one."""

    key: str
    unit: str = ""
    field: str = ""  # the config's attribute, where it is not named as the key
    minimum: float | None = None
    positive: bool = False
    maximum: float | None = None
    integer: bool = False


@dataclass(frozen=True)
class Vector:
    """``length`` numbers in ``unit``, kept as a tuple of floats; ``positive``: each > 0."""

    key: str
    unit: str = ""
    field: str = ""
    length: int = 3
    positive: bool = False


@dataclass(frozen=True)
class Choice:
    """A string among ``choices``; ``rule`` the words of a refusal ("must be one of …" by
    default). ``lenient``: a string that is no string (already refused) is taken as the
    default, so that the checks relating it to other keys still read a value."""

    key: str
    choices: tuple[str, ...]
    rule: str = ""
    field: str = ""
    lenient: bool = False


@dataclass(frozen=True)
class Flag:
    """true or false."""

    key: str
    field: str = ""


@dataclass(frozen=True)
class Text:
    """A non-empty string."""

    key: str
    field: str = ""


Field = Number | Vector | Choice | Flag | Text


def positive(*keys: tuple[str, str]) -> tuple[Number, ...]:
    """Numbers that must be > 0, each given as (key, unit)."""
    return tuple(Number(key, unit, positive=True) for key, unit in keys)


def _field_read(rd: TableReader, t: dict[str, Any], path: str, spec: Field,
                default: Any) -> Any:  # fmt: skip
    """What ``spec`` reads from table ``t`` (None: absent without a default, or refused)."""
    full = f"{path}.{spec.key}"
    if isinstance(spec, Number):
        v = rd.number(t, spec.key, path, spec.unit, required=False, default=default,
                      minimum=spec.minimum, positive=spec.positive, maximum=spec.maximum,
                      integer=spec.integer)  # fmt: skip
        return int(v) if v is not None and spec.integer else v
    if isinstance(spec, Vector):
        vec = rd.vector(t, spec.key, path, spec.unit, length=spec.length, required=False)
        if vec is None:
            return None
        if spec.positive and np.any(vec <= 0.0):
            rd.error(full, vec.tolist(), spec.unit, "must contain only values > 0")
            return None
        return tuple(float(x) for x in vec)
    if isinstance(spec, Choice):
        s = rd.string(t, spec.key, path, required=False, default=default)
        if spec.lenient:
            s = s or default
        if s not in spec.choices:
            rd.error(full, s, "", spec.rule or f"must be one of {', '.join(spec.choices)}")
        return s
    if isinstance(spec, Flag):
        if spec.key not in t:
            return None
        if not isinstance(t[spec.key], bool):
            rd.error(full, t[spec.key], "", "must be true or false")
            return None
        return t[spec.key]
    return rd.string(t, spec.key, path, required=False, default=default)


def read_fields(rd: TableReader, t: dict[str, Any], path: str, specs: Iterable[Field],
                defaults: Any, into: dict[str, Any]) -> None:  # fmt: skip
    """Each of ``specs`` read from table ``t`` (at ``path``) in order, its refusals recorded
    in ``rd``; what was read (not None) into ``into[field]``. A key absent takes
    ``defaults``' attribute of the field's name."""
    for spec in specs:
        name = spec.field or spec.key
        v = _field_read(rd, t, path, spec, getattr(defaults, name, None))
        if v is not None:
            into[name] = v


C = TypeVar("C")


def read_section(rd: TableReader, data: dict[str, Any], key: str, allowed: Iterable[str],
                 config: Callable[..., C], read: Callable[[dict[str, Any], dict[str, Any]], None],
                 ) -> C | None:  # fmt: skip
    """The optional top-level section ``key`` as a ``config``: absent, ``config()``; else its
    keys checked against ``allowed``, ``read(table, fields)`` fills the config's fields (its
    refusals recorded in ``rd``), and the config of them — None where anything was refused."""
    n0 = len(rd.errors)
    t = rd.section(data, key, allowed)
    if t is None:
        return config()
    vals: dict[str, Any] = {}
    read(t, vals)
    if len(rd.errors) > n0:
        return None
    return config(**vals)
