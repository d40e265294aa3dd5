"""Load plain mappings (parsed YAML) into frozen dataclasses, strictly.

Used for ``params.yaml`` (``pipeline.params``) and dataset descriptors (``ingest.config``); it
lives in ``ingest`` because ``pipeline`` depends on ``ingest``, never the reverse.

The rules: every key must be a field (a misspelled key is an error with a suggestion); a field
without a default must be present; values must have the annotated type (``int`` is accepted
for ``float``, ``bool`` is never accepted for ``int`` or ``float``); lists become tuples.
Errors name the dotted key path, e.g. ``filters.tc_ukf.alpha``; the caller chooses the error
class (``ParamsError``, ``ConfigError`` ...) through ``error``. A dataclass checks its own
values in ``__post_init__`` by raising ``FieldError(field, reason)``; the loader prefixes the
path of the dataclass.

Supported annotations: ``bool``, ``int``, ``float``, ``str``, ``Literal[...]``,
``tuple[T, ...]``, ``tuple[T1, T2]``, ``dict[str, T]`` (also ``Mapping``), ``T | None``, and
nested frozen dataclasses.
"""

from __future__ import annotations

import dataclasses
import difflib
import types
import typing
from collections.abc import Mapping
from typing import Any, TypeVar

T = TypeVar("T")


class FieldError(ValueError):
    """Raised by a dataclass's ``__post_init__`` for a bad value of one of its fields."""

    def __init__(self, field: str, reason: str) -> None:
        self.field = field
        self.reason = reason
        super().__init__(f"{field}: {reason}")

    def __reduce__(self) -> tuple[Any, ...]:
        # picklable (errors cross process-pool boundaries): rebuild from the fields
        return (type(self), (self.field, self.reason))


class KeyPathError(Exception):
    """A value at a dotted key path is wrong. Subclassed by each caller's error type.

    Args:
        key_path: dotted path of the offending key, e.g. ``run.filters[2]``.
        reason: what is wrong.
        source: the file, if known.
    """

    def __init__(self, key_path: str, reason: str, *, source: str | None = None) -> None:
        self.key_path = key_path
        self.reason = reason
        self.source = source
        where = f"{source}: " if source else ""
        super().__init__(f"{where}{key_path or '<top level>'}: {reason}")

    def __reduce__(self) -> tuple[Any, ...]:
        # picklable (errors cross process-pool boundaries): rebuild from the fields
        return (_rebuild_key_path_error, (type(self), self.key_path, self.reason, self.source))


def _rebuild_key_path_error(
    cls: type[KeyPathError], key_path: str, reason: str, source: str | None
) -> KeyPathError:
    return cls(key_path, reason, source=source)


def load_dataclass(
    cls: type[T],
    data: object,
    path: str = "",
    *,
    source: str | None = None,
    error: type[KeyPathError] = KeyPathError,
) -> T:
    """Build ``cls`` (a dataclass) from ``data``; raises ``error`` naming the key path."""
    try:
        value = _convert(cls, data, path, source)
    except KeyPathError as err:
        if type(err) is error:
            raise
        raise error(err.key_path, err.reason, source=err.source) from err
    return typing.cast(T, value)


def _join(path: str, key: str) -> str:
    return f"{path}.{key}" if path else key


def _type_name(tp: Any) -> str:
    if isinstance(tp, type):
        return tp.__name__
    return str(tp).replace("typing.", "")


def _convert(tp: Any, value: object, path: str, source: str | None) -> Any:
    if dataclasses.is_dataclass(tp) and isinstance(tp, type):
        return _convert_dataclass(tp, value, path, source)
    origin = typing.get_origin(tp)
    if origin in (types.UnionType, typing.Union):
        return _convert_union(tp, value, path, source)
    if origin is typing.Literal:
        return _convert_literal(tp, value, path, source)
    if origin is tuple:
        return _convert_tuple(tp, value, path, source)
    if origin in (dict, Mapping):
        return _convert_mapping(tp, value, path, source)
    return _convert_scalar(tp, value, path, source)


def _convert_union(tp: Any, value: object, path: str, source: str | None) -> Any:
    args = typing.get_args(tp)
    if value is None and type(None) in args:
        return None
    inner = [a for a in args if a is not type(None)]
    if len(inner) == 1:
        return _convert(inner[0], value, path, source)
    for a in inner:
        try:
            return _convert(a, value, path, source)
        except KeyPathError:
            continue
    raise KeyPathError(path, f"expected {_type_name(tp)}, got {value!r}", source=source)


def _convert_literal(tp: Any, value: object, path: str, source: str | None) -> Any:
    args = typing.get_args(tp)
    # True == 1 in Python: a bool only matches a bool choice.
    if any(value == a and isinstance(value, bool) == isinstance(a, bool) for a in args):
        return value
    choices = ", ".join(repr(a) for a in args)
    raise KeyPathError(path, f"{value!r} is not one of {choices}", source=source)


def _convert_tuple(tp: Any, value: object, path: str, source: str | None) -> Any:
    args = typing.get_args(tp)
    if not isinstance(value, list | tuple):
        raise KeyPathError(
            path, f"expected a list, got {type(value).__name__} {value!r}", source=source
        )
    if len(args) == 2 and args[1] is Ellipsis:
        return tuple(_convert(args[0], v, f"{path}[{i}]", source) for i, v in enumerate(value))
    if len(value) != len(args):
        raise KeyPathError(
            path, f"expected a list of {len(args)} items, got {len(value)}", source=source
        )
    return tuple(
        _convert(a, v, f"{path}[{i}]", source)
        for i, (a, v) in enumerate(zip(args, value, strict=True))
    )


def _convert_mapping(tp: Any, value: object, path: str, source: str | None) -> Any:
    if not isinstance(value, Mapping):
        raise KeyPathError(path, f"expected a mapping, got {type(value).__name__}", source=source)
    key_t, val_t = typing.get_args(tp)
    out = {}
    for k, v in value.items():
        if not isinstance(k, str):
            raise KeyPathError(_join(path, str(k)), "keys must be strings", source=source)
        out[_convert(key_t, k, _join(path, k), source)] = _convert(val_t, v, _join(path, k), source)
    return types.MappingProxyType(out)


_SCALARS: dict[Any, tuple[tuple[type, ...], str]] = {
    bool: ((bool,), "true or false"),
    int: ((int,), "an integer"),
    float: ((int, float), "a number"),
    str: ((str,), "a string"),
}


def _convert_scalar(tp: Any, value: object, path: str, source: str | None) -> Any:
    if tp is Any:
        return value
    if tp not in _SCALARS:
        raise TypeError(f"paramtypes cannot load annotation {tp!r} at {path}")  # programming error
    accepted, name = _SCALARS[tp]
    if isinstance(value, accepted) and (tp is bool or not isinstance(value, bool)):
        return float(value) if tp is float else value  # type: ignore[arg-type]
    raise KeyPathError(path, f"expected {name}, got {value!r}", source=source)


def _convert_dataclass(cls: type, value: object, path: str, source: str | None) -> Any:
    if value is None:
        raise KeyPathError(
            path, f"section is empty; expected the keys of {cls.__name__}", source=source
        )
    if not isinstance(value, Mapping):
        raise KeyPathError(
            path, f"expected a mapping ({cls.__name__}), got {value!r}", source=source
        )
    hints = typing.get_type_hints(cls)
    fields = {f.name: f for f in dataclasses.fields(cls) if f.init}
    for key in value:
        if key not in fields:
            near = difflib.get_close_matches(str(key), list(fields), n=1, cutoff=0.6)
            hint = f"; did you mean {near[0]!r}?" if near else f"; known keys: {sorted(fields)}"
            raise KeyPathError(_join(path, str(key)), f"unknown key{hint}", source=source)
    kwargs = {}
    for name, f in fields.items():
        key_path = _join(path, name)
        if name in value:
            kwargs[name] = _convert(hints[name], value[name], key_path, source)
        elif f.default is dataclasses.MISSING and f.default_factory is dataclasses.MISSING:
            raise KeyPathError(key_path, f"missing (required by {cls.__name__})", source=source)
    try:
        return cls(**kwargs)
    except FieldError as err:
        raise KeyPathError(_join(path, err.field), err.reason, source=source) from err


def to_plain(obj: Any) -> Any:
    """A dataclass tree back to plain dicts/lists (for hashing and provenance)."""
    if dataclasses.is_dataclass(obj) and not isinstance(obj, type):
        return {f.name: to_plain(getattr(obj, f.name)) for f in dataclasses.fields(obj)}
    if isinstance(obj, Mapping):
        return {k: to_plain(v) for k, v in obj.items()}
    if isinstance(obj, tuple | list):
        return [to_plain(v) for v in obj]
    return obj
