"""Input checks shared by every layer: one message format and one rule for each common test.

A refused value raises ``ValueError`` (or the caller's subclass of it) with the message
``{where}: {name} = {value} is not allowed; expected {allowed}``: where the value came from, the value
(arrays shortened by :func:`short`) and what is allowed.
"""

from __future__ import annotations

import dataclasses
import difflib
import enum
import math
import numbers
import typing
from collections.abc import Callable, Iterable, Mapping
from typing import NoReturn

import numpy as np

from warpdem.errors import InputError

_SHOWN = 12  # most numbers of an array that a message prints


def short(value) -> str:
    """``repr(value)`` for a message; an array prints at most a dozen numbers and, when that does not show
    its shape (a large, empty or multi-dimensional array), its shape too. A bool prints as the user wrote it in
    TOML, JSON or ``--set`` (true, false)."""
    if isinstance(value, (bool, np.bool_)):
        return "true" if value else "false"
    if not isinstance(value, np.ndarray):
        return repr(value)
    text = np.array2string(value, precision=6, threshold=_SHOWN, separator=", ")
    if value.ndim > 1 or value.size == 0 or value.size > _SHOWN:
        text += f" (shape {value.shape})"
    return text


def not_allowed(where: str, name: str, value, allowed: str) -> str:
    """The message refusing ``name = value`` at ``where`` ("" for none), saying what is ``allowed``."""
    head = f"{where}: " if where else ""
    return f"{head}{name} = {short(value)} is not allowed; expected {allowed}"


def fail(where: str, name: str, value, allowed: str, error: type[ValueError] = InputError) -> NoReturn:
    """Raise ``error`` refusing ``name = value`` (see :func:`not_allowed`)."""
    raise error(not_allowed(where, name, value, allowed))


def check(cond, where: str, name: str, value, allowed: str, error: type[ValueError] = InputError) -> None:
    """Refuse ``name = value`` unless ``cond`` holds."""
    if not cond:
        fail(where, name, value, allowed, error)


def is_finite(value) -> bool:
    """True when ``float(value)`` is finite: numbers and one-element arrays, but no strings and no bools (a
    True given for a density is a mistake, not 1 kg/m^3)."""
    if isinstance(value, (str, bytes, bool, np.bool_)):
        return False
    try:
        return math.isfinite(float(value))
    except (TypeError, ValueError):
        return False


def is_number(value) -> bool:
    """True for a real number that is not a bool (Python or NumPy scalars)."""
    return isinstance(value, numbers.Real) and not isinstance(value, (bool, np.bool_))


def check_number(
    where: str,
    name: str,
    value,
    ok: Callable[[float], bool],
    allowed: str,
    error: type[ValueError] = InputError,
) -> float:
    """``float(value)``, refused unless it is finite and ``ok`` of it holds."""
    check(is_finite(value) and ok(float(value)), where, name, value, allowed, error)
    return float(value)


def positive(where: str, name: str, value, allowed: str = "a finite value > 0") -> float:
    """``float(value)``, refused unless finite and > 0."""
    return check_number(where, name, value, lambda v: v > 0.0, allowed)


def integer(where: str, name: str, value, minimum: int, allowed: str = "") -> int:
    """``int(value)``, refused unless ``value`` is an integer (not a bool) >= ``minimum``; ``allowed``
    defaults to "an integer >= minimum"."""
    ok = isinstance(value, (int, np.integer)) and not isinstance(value, bool) and value >= minimum
    check(ok, where, name, value, allowed or f"an integer >= {minimum}")
    return int(value)


def finite_number(
    where: str, name: str, value, allowed: str = "a finite number", error: type[ValueError] = InputError
) -> float:
    """``float(value)``, refused unless ``value`` is a finite real number (not a bool, not a string)."""
    check(is_number(value) and math.isfinite(value), where, name, value, allowed, error)
    return float(value)


def float_array(where: str, name: str, value, allowed: str) -> np.ndarray:
    """``value`` as a new float64 array; refused (naming ``allowed``) when it is not numbers."""
    try:
        return np.array(value, dtype=np.float64)
    except (TypeError, ValueError):
        pass
    fail(where, name, value, allowed)


def vec3(where: str, name: str, value) -> tuple[float, float, float]:
    """Three finite numbers (a sequence or an array of shape (3,)) as a tuple of floats; a nested one, such as
    [[x, y, z]], is refused."""
    try:
        a = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        a = None
    check(
        a is not None and a.shape == (3,) and bool(np.all(np.isfinite(a))), where, name, value, "three finite numbers"
    )
    return (float(a[0]), float(a[1]), float(a[2]))


def readonly(value, dtype=None) -> np.ndarray:
    """A C-contiguous read-only copy of ``value`` (of ``dtype`` when given): a frozen dataclass's array that no
    caller's later write can change."""
    a = np.array(value, dtype=dtype, order="C")
    a.setflags(write=False)
    return a


def enum_value(cls: type[enum.Enum], where: str, name: str, value, aliases: Mapping[str, str] | None = None):
    """The member of enum ``cls`` that ``value`` names: a member, its name in any case (``-`` and spaces
    read as ``_``; ``aliases`` maps other names to member names) or its integer value."""
    if isinstance(value, cls):
        return value
    if isinstance(value, str):
        key = value.strip().upper().replace("-", "_").replace(" ", "_")
        key = (aliases or {}).get(key, key)
        if key in cls.__members__:
            return cls[key]
    elif isinstance(value, (int, np.integer)) and int(value) in {m.value for m in cls}:
        return cls(int(value))
    fail(where, name, value, "one of " + ", ".join(cls.__members__))


def did_you_mean(word, choices: Iterable) -> str:
    """`` (did you mean 'x'?)`` naming the choice nearest to ``word`` when one is near enough to be what a
    misspelt ``word`` meant, else ""."""
    near = difflib.get_close_matches(str(word), [str(c) for c in choices], n=1, cutoff=0.6)
    return f" (did you mean {near[0]!r}?)" if near else ""


def number_fields(cls) -> dict[str, type]:
    """The fields of dataclass ``cls`` annotated ``float`` or ``int`` (or either ``| None``), in field order,
    each with that type: the fields a bare number sets."""
    hints = typing.get_type_hints(cls)
    out = {}
    for f in dataclasses.fields(cls):
        kinds = [t for t in (hints[f.name], *typing.get_args(hints[f.name])) if t in (float, int)]
        if kinds:
            out[f.name] = kinds[0]
    return out


def typed_number(
    where: str, name: str, value, kind: type, optional: bool = False, error: type[ValueError] = InputError
):
    """``value`` as a ``kind`` (float or int), refused unless it is a finite real number (not a bool, not a
    string) and, for an int, a whole number (2.0 reads as 2, 1.5 is refused); None passes when ``optional``."""
    if value is None and optional:
        return None
    if kind is int:
        check(
            is_number(value) and math.isfinite(value) and float(value).is_integer(),
            where,
            name,
            value,
            "a whole number" + (" or null" if optional else ""),
            error,
        )
        return int(value)
    return finite_number(where, name, value, "a finite number" + (" or null" if optional else ""), error)


def optional_fields(cls) -> set[str]:
    """The fields of dataclass ``cls`` whose annotation admits None."""
    hints = typing.get_type_hints(cls)
    return {f.name for f in dataclasses.fields(cls) if type(None) in typing.get_args(hints[f.name])}
