"""The JSON form of rkhp's results (docs/json.md): one encoder, so that a result type is JSON by
construction.

:func:`json_form` gives the value json.dumps writes:

- a dataclass or a NamedTuple: an object with one key per field, in the order of the fields; a
  class whose keys are not its fields declares ``json_keys`` (:func:`keys_of`), a tuple whose
  entries are a name, the key and the attribute it reads (a field, a property, a class constant or
  a method without arguments, which is called), or a pair (key, attribute name), the name dotted
  to read through attributes (``"result.system"``);
- a type of :data:`FORMS` (or a subclass), looked up first: its registered form, e.g. a Fraction
  as the text ``"1/3"`` that Fraction reads back; a module above this one registers its own
  (:func:`register`: a tree is its bracket text);
- a dict: an object of the forms of its values (its keys as they are); a tuple or a list: a list;
- a numpy array or scalar: its Python value (``tolist``);
- None, a bool, an int, a float or a str: itself (a non-finite float is the writer's to spell,
  docs/json.md).

Anything else is a TypeError: a value without a form is a mistake, not a silent ``str``.
"""

from __future__ import annotations

import dataclasses
import inspect
from collections.abc import Callable
from fractions import Fraction

from .exact_text import fraction_text

#: the form of each registered type (looked up along the type's MRO)
FORMS: dict[type, Callable[[object], object]] = {Fraction: fraction_text}

PLAIN = (type(None), bool, int, float, str)


def register(kind: type, form: Callable[[object], object]) -> None:
    """Give the values of ``kind`` (and its subclasses) the JSON form ``form(value)``."""
    FORMS[kind] = form


def is_record(value) -> bool:
    """Whether ``value`` is a dataclass instance or a NamedTuple (encoded key by key)."""
    return (dataclasses.is_dataclass(value) and not isinstance(value, type)) or (
        isinstance(value, tuple) and hasattr(type(value), "_fields"))


def keys_of(kind: type) -> tuple[tuple[str, str], ...]:
    """The (key, attribute) pairs of a record type: its ``json_keys``, else its fields."""
    declared = getattr(kind, "json_keys", None)
    if declared is None:
        names = kind._fields if hasattr(kind, "_fields") else tuple(f.name for f in dataclasses.fields(kind))
        return tuple((name, name) for name in names)
    return tuple((entry, entry) if isinstance(entry, str) else tuple(entry) for entry in declared)


def attribute(value, name: str):
    """The attribute ``name`` of ``value`` (dotted: through attributes; a method: its value)."""
    for part in name.split("."):
        value = getattr(value, part)
        if inspect.ismethod(value):
            value = value()
    return value


def json_form(value):
    """The JSON form of ``value`` (module docstring)."""
    if isinstance(value, PLAIN):
        return value
    for kind in type(value).__mro__:
        if kind in FORMS:
            return FORMS[kind](value)
    if is_record(value):
        return {key: json_form(attribute(value, name)) for key, name in keys_of(type(value))}
    if isinstance(value, dict):
        return {key: json_form(v) for key, v in value.items()}
    if isinstance(value, list | tuple):
        return [json_form(v) for v in value]
    if hasattr(value, "tolist"):  # numpy arrays and scalars
        return value.tolist()
    raise TypeError(f"no JSON form for a value of type {type(value).__name__}")
