"""Experiment metadata of a result store: the key format, defined once, and a typed read-only view.

The store's ``meta`` table (:meth:`compare.run.store.Store.meta`) maps text keys to JSON
values, and a report folder's ``report.json`` keeps that mapping as it is. A key is
``<kind>:<name>``: the kind says what the entry is (:class:`MetaKind`), the name which
experiment, method, fingerprint or instance it is about. That format is spelled here
only: writers build keys with :func:`meta_key`, readers get a :class:`StoreMeta`
(:meth:`StoreMeta.parse`), one read-only mapping per kind, whose
:meth:`StoreMeta.to_mapping` gives back the raw mapping exactly (so old stores and
shipped report folders read and write as before).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from enum import Enum
from types import MappingProxyType
from typing import Any

__all__ = ["MetaKind", "MetaError", "meta_key", "parse_meta_key", "entries_of", "StoreMeta", "MethodMeta",
           "FingerprintMeta"]

_SEPARATOR = ":"


class MetaKind(str, Enum):
    """What a meta entry is; its value is the prefix of the entry's key."""

    #: Experiment -> the spec's TOML text.
    SPEC = "spec"
    #: Experiment -> the report sections it asks for (list of str).
    SECTIONS = "sections"
    #: Experiment -> the (first, second) method or label pairs it asks to compare (list of 2-lists).
    PAIRS = "pairs"
    #: Experiment -> the ``compare run`` command that computed it (str).
    COMMAND = "command"
    #: Experiment -> where its runs were computed (:func:`compare.run.environment.environment`).
    ENVIRONMENT = "environment"
    #: Method name -> what it declares (label, summary, produces, path_param, fingerprint).
    METHOD = "method"
    #: Code fingerprint -> the module hashes and package versions behind it.
    FINGERPRINT = "fingerprint"
    #: Instance key (:func:`compare.run.records.canonical_key` of its spec) -> the facts the runner stored.
    INSTANCE = "instance"


class MetaError(ValueError):
    """A meta entry whose value does not have the shape of its kind: a one-line message naming the key."""


def meta_key(kind: MetaKind | str, name: str) -> str:
    """The store key of the ``kind`` entry about ``name``: ``"<kind>:<name>"``.

    ValueError for a kind that is not a :class:`MetaKind`.
    """
    return f"{MetaKind(kind).value}{_SEPARATOR}{name}"


def parse_meta_key(key: str) -> tuple[MetaKind, str] | None:
    """``(kind, name)`` of a key written by :func:`meta_key`; None for any other key."""
    prefix, separator, name = key.partition(_SEPARATOR)
    if not separator:
        return None
    try:
        return MetaKind(prefix), name
    except ValueError:
        return None


def entries_of(raw: Mapping[str, Any], kind: MetaKind) -> dict[str, Any]:
    """Name -> value, as stored (not copied, not checked), of the entries of ``kind`` in ``raw``."""
    out = {}
    for key, value in raw.items():
        parsed = parse_meta_key(key)
        if parsed is not None and parsed[0] is kind:
            out[parsed[1]] = value
    return out


def _frozen(value):
    """A read-only copy of a JSON value: objects become mapping proxies, arrays tuples."""
    if isinstance(value, Mapping):
        return MappingProxyType({k: _frozen(v) for k, v in value.items()})
    if isinstance(value, (list, tuple)):
        return tuple(_frozen(v) for v in value)
    return value


def _thawed(value):
    """The JSON value :func:`_frozen` was made from (fresh dicts and lists)."""
    if isinstance(value, Mapping):
        return {k: _thawed(v) for k, v in value.items()}
    if isinstance(value, tuple):
        return [_thawed(v) for v in value]
    return value


_EMPTY: Mapping = MappingProxyType({})


@dataclass(frozen=True)
class MethodMeta:
    """What a method declared when its runs were stored (a ``method:<name>`` entry).

    ``stored`` is the entry as stored, read-only; the properties read it with the
    defaults a store written by any version of the runner needs.
    """

    stored: Mapping[str, Any]

    @property
    def label(self) -> str | None:
        return self.stored.get("label")

    @property
    def summary(self) -> str | None:
        return self.stored.get("summary")

    @property
    def produces(self) -> tuple[str, ...]:
        """The report products the method declares (``training_curve``, ``topology_path``, ...)."""
        return tuple(self.stored.get("produces", ()))

    @property
    def path_param(self) -> str | None:
        """The hyperparameter along the method's topology path, if it declares one."""
        return self.stored.get("path_param")

    @property
    def fingerprint(self) -> str | None:
        return self.stored.get("fingerprint")

    def to_json(self) -> dict:
        return _thawed(self.stored)


@dataclass(frozen=True)
class FingerprintMeta:
    """The code behind a fingerprint (a ``fingerprint:<fp>`` entry): module hashes and package versions."""

    stored: Mapping[str, Any]

    @property
    def modules(self) -> Mapping[str, str]:
        return self.stored.get("modules", _EMPTY)

    @property
    def versions(self) -> Mapping[str, str]:
        return self.stored.get("versions", _EMPTY)

    def to_json(self) -> dict:
        return _thawed(self.stored)


def _text(key: str, value) -> str:
    if not isinstance(value, str):
        raise MetaError(f"meta entry {key!r} must be text, got {type(value).__name__}")
    return value


def _object(key: str, value) -> Mapping:
    if not isinstance(value, Mapping):
        raise MetaError(f"meta entry {key!r} must be a JSON object, got {type(value).__name__}")
    return _frozen(value)


def _names(key: str, value) -> tuple[str, ...]:
    if not (isinstance(value, (list, tuple)) and all(isinstance(v, str) for v in value)):
        raise MetaError(f"meta entry {key!r} must be a list of section names, got {value!r:.80}")
    return tuple(value)


def _pairs(key: str, value) -> tuple[tuple[str, str], ...]:
    if not (isinstance(value, (list, tuple)) and all(
            isinstance(p, (list, tuple)) and len(p) == 2 and all(isinstance(x, str) for x in p) for p in value)):
        raise MetaError(f"meta entry {key!r} must be a list of [first, second] name pairs, got {value!r:.80}")
    return tuple(tuple(p) for p in value)


#: Per kind: the StoreMeta field holding its entries, how a stored value is read, how it is written back.
_KINDS = {
    MetaKind.SPEC: ("specs", _text, _thawed),
    MetaKind.SECTIONS: ("sections", _names, _thawed),
    MetaKind.PAIRS: ("pairs", _pairs, _thawed),
    MetaKind.COMMAND: ("commands", _text, _thawed),
    MetaKind.ENVIRONMENT: ("environments", _object, _thawed),
    MetaKind.METHOD: ("methods", lambda key, value: MethodMeta(_object(key, value)), MethodMeta.to_json),
    MetaKind.FINGERPRINT: ("fingerprints", lambda key, value: FingerprintMeta(_object(key, value)),
                           FingerprintMeta.to_json),
    MetaKind.INSTANCE: ("instances", _object, _thawed),
}


def _empty() -> Mapping:
    return _EMPTY


@dataclass(frozen=True)
class StoreMeta:
    """A store's meta, one read-only mapping per kind of entry, name -> typed value.

    Attributes
    ----------
    specs : Mapping[str, str]
        Experiment -> its spec's TOML text.
    sections : Mapping[str, tuple[str, ...]]
        Experiment -> the report sections it asks for.
    pairs : Mapping[str, tuple[tuple[str, str], ...]]
        Experiment -> the (first, second) pairs it asks to compare.
    commands : Mapping[str, str]
        Experiment -> the ``compare run`` command that computed it.
    environments : Mapping[str, Mapping]
        Experiment -> where its runs were computed.
    methods : Mapping[str, MethodMeta]
        Method name -> what it declared.
    fingerprints : Mapping[str, FingerprintMeta]
        Code fingerprint -> the code behind it.
    instances : Mapping[str, Mapping]
        Instance key -> the facts the runner stored.
    unknown : Mapping[str, Any]
        Key -> value of every entry of no known kind (a newer version's, or a
        user's), kept so that :meth:`to_mapping` writes it back.

    Values are read-only (JSON objects as mapping proxies, arrays as tuples).
    """

    specs: Mapping[str, str] = field(default_factory=_empty)
    sections: Mapping[str, tuple[str, ...]] = field(default_factory=_empty)
    pairs: Mapping[str, tuple[tuple[str, str], ...]] = field(default_factory=_empty)
    commands: Mapping[str, str] = field(default_factory=_empty)
    environments: Mapping[str, Mapping[str, Any]] = field(default_factory=_empty)
    methods: Mapping[str, MethodMeta] = field(default_factory=_empty)
    fingerprints: Mapping[str, FingerprintMeta] = field(default_factory=_empty)
    instances: Mapping[str, Mapping[str, Any]] = field(default_factory=_empty)
    unknown: Mapping[str, Any] = field(default_factory=_empty)
    # The raw keys in their order, so that to_mapping() iterates as the raw mapping did.
    _order: tuple[str, ...] = field(default=(), repr=False, compare=False)

    @classmethod
    def parse(cls, raw: Mapping[str, Any] | None) -> StoreMeta:
        """The view of ``raw`` (:meth:`compare.run.store.Store.meta`, or ``report.json``'s ``meta``).

        Keys of no known kind are kept in :attr:`unknown`; a value that does not
        have its kind's shape is a :class:`MetaError` naming its key.
        """
        raw = raw or {}
        kinds = {name: {} for name, *_ in _KINDS.values()}
        unknown = {}
        for key, value in raw.items():
            parsed = parse_meta_key(key)
            if parsed is None:
                unknown[key] = _frozen(value)
                continue
            kind, name = parsed
            attribute, read, _ = _KINDS[kind]
            kinds[attribute][name] = read(key, value)
        return cls(**{k: MappingProxyType(v) for k, v in kinds.items()}, unknown=MappingProxyType(unknown),
                   _order=tuple(raw))

    @classmethod
    def of(cls, meta: StoreMeta | Mapping[str, Any] | None) -> StoreMeta:
        """``meta`` itself if it is a StoreMeta, else :meth:`parse` of it."""
        return meta if isinstance(meta, StoreMeta) else cls.parse(meta)

    def to_mapping(self) -> dict[str, Any]:
        """The raw mapping this view was parsed from: equal keys and JSON values, fresh copies."""
        out = {}
        for kind, (attribute, _, write) in _KINDS.items():
            for name, value in getattr(self, attribute).items():
                out[meta_key(kind, name)] = write(value)
        out.update((key, _thawed(value)) for key, value in self.unknown.items())
        if set(self._order) == set(out):
            out = {key: out[key] for key in self._order}
        return out
