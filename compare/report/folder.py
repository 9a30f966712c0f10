"""A report folder that rebuilds itself: ``runs.csv``, ``curves.csv`` and ``report.json``.

The result store is not shipped with a report, so everything the report is drawn
from is written into its folder as plain files, losslessly:

``runs.csv``
    One row per design. The columns of earlier reports come first, in their order
    (readers of those keep working), then ``instance`` (the canonical JSON of the
    instance spec), the instance facts (``instance_nodes``, ``plant_links``,
    ``comm_links``), ``experiment``, ``controller_kind`` and the timings of the run
    that made the design (``run_seconds``, ``run_designs``, ``run_peak_mb``); after
    them the instance facts added later (``nodes``, ``inputs``, ``actuated_nodes``,
    ``open_loop_radius``) and the run's measurements added later
    (``run_scoring_seconds``, ``run_baseline_mb``), each only where some design has it,
    so that a folder written before them is rewritten byte for byte.
    Floats are written with ``repr``, so they read back exactly; ``extras`` holds
    the scalar extras as JSON.
``curves.csv``
    The training curves among the extras (``{"step": [...], "cost": [...]}``, such
    as ``curve`` and ``l1_curve``), long format: ``run_key, idx, name, step, value``.
``report.json``
    The store's meta, the experiments' members, the count of superseded runs, the
    software versions, the supports of the controllers the topology figure draws
    and the drawing of their instance (its graphs and node colours, as the runner
    stored them with its facts), the styles each figure drew, and what a CSV cell
    cannot hold: the other non-scalar extras (lists, nested
    dicts, None) and which text fields are None rather than empty.

:func:`write_folder` writes them (deterministically: writing the same data twice
gives byte-identical files); :func:`read_folder` reads them back into a
:class:`FolderData` whose records equal the store's field by field.
"""

from __future__ import annotations

import csv
import io
import json
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ..run.records import Records, as_records, canonical_key, row_problem
from ..run.drawing import InstanceDrawing
from ..run.meta import StoreMeta

__all__ = ["write_folder", "read_folder", "FolderData", "FolderError", "StoredSupport", "topology_supports",
           "FOLDER_FILES", "FOLDER_FORMAT"]

#: Version of the layout of ``report.json`` (and the files beside it).
FOLDER_FORMAT = 1

RUNS, CURVES, REPORT = "runs.csv", "curves.csv", "report.json"
#: The files :func:`write_folder` writes, by the key it returns them under.
FOLDER_FILES = {"csv": RUNS, "curves": CURVES, "json": REPORT}

#: The columns of runs.csv before this module (after the ``instance_<field>`` ones), in their order.
_OLD_COLUMNS = ("label", "method", "params", "status", "cost", "cost_stderr", "cost_kind", "links", "self_loops",
                "info_model", "seconds", "message", "extras", "run_key", "idx", "fingerprint")
_NEW_COLUMNS = ("instance", "instance_nodes", "plant_links", "comm_links", "experiment", "controller_kind",
                "run_seconds", "run_designs", "run_peak_mb")
_CURVE_COLUMNS = ("run_key", "idx", "name", "step", "value")

#: DesignRecord fields written as text (a None is listed in report.json's ``null_text``).
_TEXT = ("label", "method", "status", "cost_kind", "info_model", "message", "run_key", "fingerprint", "experiment",
         "controller_kind")
#: DesignRecord fields written as numbers ('' = None); ints stay ints, floats floats.
_NUMBERS = ("cost", "cost_stderr", "links", "self_loops", "seconds", "run_seconds", "run_designs", "run_peak_mb")
#: Run measurements added later (DesignRecord fields, numbers), written last when some design has them;
#: a folder written before them has none, and its records read them as None (unknown).
_LATER_RUN_COLUMNS = ("run_scoring_seconds", "run_baseline_mb")
#: Instance facts: runs.csv column -> InstanceRecord attribute and the key the runner stores it under.
_FACTS = {"instance_nodes": "n", "plant_links": "plant_links", "comm_links": "comm_links"}
#: Facts added later, written after every other column when some instance has them; a folder written
#: before them (or from a store without them) has none.
#: runs.csv column -> (InstanceRecord attribute, the runner's fact key).
_LATER_FACTS = {"nodes": ("node_count", "nodes"), "inputs": ("inputs", "inputs"),
                "actuated_nodes": ("actuated", "actuated"), "open_loop_radius": ("radius", "radius")}


class FolderError(ValueError):
    """A report folder without its files, or with malformed ones: a one-line message naming the file."""


@dataclass(frozen=True)
class StoredSupport:
    """What a report folder keeps of a controller: its support, (n, n) booleans (True = link)."""

    support: np.ndarray


# -- writing ------------------------------------------------------------------------

def _is_scalar(value) -> bool:
    """Whether runs.csv's ``extras`` column holds this extra (scalars only, as it always has)."""
    return isinstance(value, (int, float, str, bool))


def _is_number(value) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool)


def _is_curve(value) -> bool:
    """A training curve: ``{"step": [...], "cost": [...]}``, numbers of equal, nonzero length."""
    return (isinstance(value, Mapping) and set(value) == {"step", "cost"}
            and all(isinstance(value[k], list) for k in ("step", "cost"))
            and 0 < len(value["step"]) == len(value["cost"])
            and all(_is_number(v) for v in (*value["step"], *value["cost"])))


def _design_key(run_key: str, idx: int) -> str:
    return f"{run_key}/{idx}"


def _cell(value) -> str:
    """A CSV cell: repr for floats (exact round trip, also for numpy floats), '' for None."""
    if value is None:
        return ""
    if isinstance(value, float):
        return float.__repr__(value)
    return str(value)


def _number_json(value) -> str:
    # json writes floats with repr (NaN and Infinity included) and keeps ints apart from floats.
    return json.dumps(value)


def _runs_rows(records: Records) -> Iterable[list]:
    instance_fields = sorted({k for inst in records.instances for k in inst.spec})
    later = [c for c, (attr, _) in _LATER_FACTS.items()
             if any(getattr(i, attr) is not None for i in records.instances)]
    measured = [c for c in _LATER_RUN_COLUMNS if any(getattr(r, c) is not None for r in records)]
    yield [f"instance_{k}" for k in instance_fields] + list(_OLD_COLUMNS) + list(_NEW_COLUMNS) + later + measured
    for r in records:
        values = {name: getattr(r, name) for name in (*_TEXT, *_NUMBERS, *measured, "idx")}
        values.update(
            params=r.params_key, instance=r.instance.key,
            extras=json.dumps({k: v for k, v in r.extras.items() if _is_scalar(v)}, sort_keys=True),
            **{column: getattr(r.instance, attr) for column, attr in _FACTS.items()},
        )
        values.update({column: getattr(r.instance, _LATER_FACTS[column][0]) for column in later})
        row = [r.instance.spec.get(k, "") for k in instance_fields]
        yield row + [_cell(values[c]) for c in (*_OLD_COLUMNS, *_NEW_COLUMNS, *later, *measured)]


def _curve_rows(records: Records) -> Iterable[list]:
    yield list(_CURVE_COLUMNS)
    for r in records:
        for name in sorted(r.extras):
            curve = r.extras[name]
            if _is_curve(curve):
                for step, value in zip(curve["step"], curve["cost"]):
                    yield [r.run_key, r.idx, name, _number_json(step), _number_json(value)]


def _write_csv(path: Path, rows: Iterable[list]) -> None:
    with path.open("w", newline="", encoding="utf-8") as handle:
        csv.writer(handle).writerows(rows)


def _support_entry(support) -> dict | None:
    if support is None:
        return None
    support = np.asarray(support)
    if support.ndim != 2 or support.shape[0] != support.shape[1]:
        raise ValueError(f"a support must be a square matrix, got shape {support.shape}")
    return {"n": int(support.shape[0]), "nonzero": np.argwhere(support != 0).tolist()}


def write_folder(records, out, *, meta: Mapping, members: Mapping, superseded: int, software: Mapping,
                 supports: Mapping | None = None, figures: Mapping | None = None) -> dict[str, Path]:
    """Write ``runs.csv``, ``curves.csv`` and ``report.json``: all a report is drawn from.

    Parameters
    ----------
    records : Records
        The designs, written in this order (:meth:`compare.run.store.Store.records`, or
        as :func:`compare.report.write_report` sorts them).
    out : str or Path
        The report folder (created).
    meta : Mapping
        :meth:`compare.run.store.Store.meta` (JSON values).
    members : Mapping
        :meth:`compare.run.store.Store.members`: experiment -> its run keys.
    superseded : int
        :meth:`compare.run.store.Store.superseded`.
    software : Mapping
        Package -> version, as the report prints them.
    supports : Mapping, optional
        ``(run_key, idx) -> (n, n) array`` (nonzero = link), or None for a design
        without one: the controllers the topology figure draws
        (:func:`topology_supports`). The drawing of these designs' instance
        (:attr:`compare.run.records.InstanceRecord.drawing`) is kept with them, so that
        the folder draws the topology figure again without a store.
    figures : Mapping, optional
        Figure stem -> label -> the (colour, marker) pairs it drew (JSON values), kept
        so that tests and readers can check the styles without parsing images.

    Returns
    -------
    dict
        ``{"csv": runs.csv, "curves": curves.csv, "json": report.json}`` paths.
    """
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    records = as_records(records)
    files = {key: out / name for key, name in FOLDER_FILES.items()}
    _write_csv(files["csv"], _runs_rows(records))
    _write_csv(files["curves"], _curve_rows(records))
    other_extras, null_text = {}, {}
    for r in records:
        key = _design_key(r.run_key, r.idx)
        other = {k: v for k, v in r.extras.items() if not _is_scalar(v) and not _is_curve(v)}
        if other:
            other_extras[key] = other
        nulls = [name for name in _TEXT if getattr(r, name) is None]
        if nulls:
            null_text[key] = nulls
    drawn = set(supports or {})
    # getattr: as in compare.report.sections._drawing_of, for a run whose records module predates drawings.
    drawings = {r.instance.key: r.instance.drawing.to_facts() for r in records
                if (r.run_key, r.idx) in drawn and getattr(r.instance, "drawing", None) is not None}
    document = {
        "format": FOLDER_FORMAT,
        "meta": dict(meta),
        "members": {name: sorted(keys) for name, keys in members.items()},
        "superseded": int(superseded),
        # Pairs, not an object: the report prints the versions in this order.
        "software": [[str(k), str(v)] for k, v in software.items()],
        "supports": {_design_key(rk, idx): _support_entry(s) for (rk, idx), s in (supports or {}).items()},
        "figures": dict(figures or {}),
        "other_extras": other_extras,
        "null_text": null_text,
    }
    if drawings:  # a folder without a topology figure is written as before drawings were kept
        document["drawings"] = drawings
    files["json"].write_text(json.dumps(document, sort_keys=True, indent=1, ensure_ascii=False) + "\n",
                             encoding="utf-8")
    return files


def topology_supports(records, meta: Mapping | StoreMeta, load_controller: Callable) -> dict[tuple[str, int], Any]:
    """The supports of the controllers the topology figure draws: ``(run_key, idx) -> array or None``.

    The same path as :func:`compare.report.write_report` picks (the first method,
    by name, that declares a ``topology_path`` in ``meta``, :meth:`compare.run.store.Store.meta`
    or its :class:`compare.run.meta.StoreMeta`), each design's ``support`` (None for
    a design whose controller has none); empty when no path has two designs.
    """
    from .sections import topology_path

    path, _ = topology_path(as_records(records), StoreMeta.of(meta))
    if len(path) < 2:
        return {}
    return {(r.run_key, r.idx): getattr(load_controller(r.run_key, r.idx), "support", None) for r in path}


# -- reading ------------------------------------------------------------------------

@dataclass(frozen=True)
class FolderData:
    """What a report folder holds: the arguments :func:`compare.report.write_report` needs.

    Attributes
    ----------
    records : Records
        Equal, field by field, to the store's records the folder was written from.
    meta : dict
        :meth:`compare.run.store.Store.meta`.
    members : dict
        Experiment -> frozenset of its run keys (:meth:`compare.run.store.Store.members`).
    superseded : int
    software : dict
        Package -> version, as the report printed them (in that order).
    supports : dict
        ``(run_key, idx)`` -> the stored support (boolean array) or None.
    figures : dict
        Figure stem -> label -> the (colour, marker) pairs it drew, as written.
    """

    records: Records
    meta: dict
    members: dict
    superseded: int
    software: dict
    supports: dict = field(repr=False)
    figures: dict = field(default_factory=dict, repr=False)

    def load_controller(self, run_key: str, idx: int = 0) -> StoredSupport | None:
        """The stored support of a design as ``.support`` (like :meth:`compare.run.store.Store.controller`).

        None for a design of the topology path without a support; KeyError for a
        design whose support the folder does not keep.
        """
        key = (run_key, int(idx))
        if key not in self.supports:
            raise KeyError(f"the report folder keeps no controller support of design ({run_key!r}, {idx})")
        support = self.supports[key]
        return None if support is None else StoredSupport(support.copy())


def _read_text(path: Path) -> str:
    try:
        # newline="": a carriage return inside a quoted CSV field (a solver message) stays one.
        with path.open(encoding="utf-8", newline="") as handle:
            return handle.read()
    except (OSError, UnicodeDecodeError) as exc:
        raise FolderError(f"{path}: cannot read: {exc}") from None


def _csv_rows(path: Path, required: tuple) -> Iterable[tuple[int, dict]]:
    """``(line, {column: cell})`` for each data row; the last column of a repeated name wins."""
    reader = csv.reader(io.StringIO(_read_text(path), newline=""))
    try:
        header = next(reader, None)
        if header is None:
            raise FolderError(f"{path}: empty file, expected a header row")
        missing = [c for c in required if c not in header]
        if missing:
            raise FolderError(f"{path}: missing columns {', '.join(missing)}")
        for row in reader:
            if len(row) != len(header):
                raise FolderError(f"{path} line {reader.line_num}: {len(row)} fields, the header has {len(header)}")
            yield reader.line_num, dict(zip(header, row))
    except csv.Error as exc:
        raise FolderError(f"{path} line {reader.line_num}: {exc}") from None


def _number(cell: str):
    """A number written by :func:`_cell` ('' = None): an int if written as one, else a float."""
    if cell == "":
        return None
    try:
        return int(cell)
    except ValueError:
        return float(cell)


def _json_value(cell: str, kind: type):
    value = json.loads(cell)
    if not isinstance(value, kind) or isinstance(value, bool):
        raise ValueError(f"expected a JSON {kind.__name__}")
    return value


#: How each runs.csv column a record is rebuilt from is read.
_PARSERS = {
    **{name: str for name in _TEXT},
    **{name: _number for name in (*_NUMBERS, *_FACTS)},
    "idx": int,
    **{name: (lambda cell: _json_value(cell, dict)) for name in ("params", "extras", "instance")},
}


def _parse_run(cells: dict) -> dict:
    """A runs.csv row as the store's dict, with its instance facts under ``"facts"``."""
    row = {}
    for name, parse in _PARSERS.items():
        try:
            row[name] = parse(cells[name])
        except ValueError as exc:  # json.JSONDecodeError included
            raise ValueError(f"column {name}: {exc}") from None
    for column in _LATER_RUN_COLUMNS:  # absent from folders written before they were measured: None
        try:
            row[column] = _number(cells.get(column, ""))
        except ValueError as exc:
            raise ValueError(f"column {column}: {exc}") from None
    row["facts"] = {attr: row.pop(column) for column, attr in _FACTS.items()}
    for column, (_, key) in _LATER_FACTS.items():
        try:
            row["facts"][key] = _number(cells.get(column, ""))
        except ValueError as exc:
            raise ValueError(f"column {column}: {exc}") from None
    return row


def _count_problem(row: dict) -> str | None:
    """Links or self-loops beyond what the instance's nodes can have: N(N - 1) directed links, N self-loops.

    N is the instance's node count where the folder holds it (``nodes``), else its states
    (``instance_nodes``, at least as many), else the spec's ``n``; no bound where none is known.
    """
    facts, spec = row["facts"], row["instance"]
    nodes = next((v for v in (facts.get("nodes"), facts.get("n"), spec.get("n"))
                  if isinstance(v, int) and not isinstance(v, bool) and v >= 0), None)
    if nodes is None:
        return None
    for name, most in (("links", nodes * (nodes - 1)), ("self_loops", nodes)):
        value = row.get(name)
        if _is_number(value) and value > most:
            return f"{name} {value!r} is more than an instance of {nodes} nodes can have (at most {most})"
    return None


def _instance_cell_problem(cells: Mapping, instance: dict) -> str | None:
    """An ``instance_<field>`` cell that is not the ``instance`` column's value of that field.

    The report reads the instance from the ``instance`` column (its canonical JSON); the
    ``instance_<field>`` columns repeat its fields for readers of the file, so a hand edit of
    one (``instance_n = twenty``) would otherwise pass unnoticed while the report showed another
    value. Numbers compare as numbers; lists and tables are not compared (the JSON holds them).
    """
    known = {*_OLD_COLUMNS, *_NEW_COLUMNS, *_LATER_FACTS, *_LATER_RUN_COLUMNS}
    for column, cell in cells.items():
        if not column.startswith("instance_") or column in known:
            continue
        name = column[len("instance_"):]
        value = instance.get(name)
        if value is None:
            same = cell == ""
        elif isinstance(value, bool) or isinstance(value, str):
            same = cell == str(value)
        elif _is_number(value):
            try:
                number = float(cell)
            except ValueError:
                same = False
            else:
                same = number == value or (number != number and value != value)  # NaN written as nan
        else:
            continue
        if not same:
            return (f"{column} {cell!r} is not the instance's {name} "
                    f"({'none' if value is None else repr(value)} in column instance)")
    return None


def _read_runs(path: Path) -> tuple[list[dict], dict[str, dict]]:
    """The rows of runs.csv as the store's dicts, and the instance facts by instance key."""
    rows, facts, seen = [], {}, {}
    for line, cells in _csv_rows(path, _OLD_COLUMNS + _NEW_COLUMNS):
        try:
            row = _parse_run(cells)
        except ValueError as exc:  # json.JSONDecodeError included
            raise FolderError(f"{path} line {line}: {_one_line(exc)}") from None
        problem = (row_problem(row)  # the store's check: a hand edit must not change the findings unnoticed
                   or _count_problem(row) or _instance_cell_problem(cells, row["instance"]))
        if problem is not None:
            raise FolderError(f"{path} line {line}: {problem}")
        key = (row["run_key"], row["idx"])
        if key in seen:
            raise FolderError(f"{path} line {line}: design ({key[0]}, {key[1]}) again (first on line {seen[key]})")
        seen[key] = line
        instance_facts = row.pop("facts")
        known = facts.setdefault(canonical_key(row["instance"]), instance_facts)
        if known != instance_facts:
            raise FolderError(f"{path} line {line}: instance facts {instance_facts} differ from an earlier "
                              f"row's {known} for the same instance")
        rows.append(row)
    return rows, facts


def _read_curves(path: Path, designs: dict) -> None:
    """Merge the curves of curves.csv into the extras of ``designs`` (``(run_key, idx) -> row``)."""
    curves: dict[tuple, dict] = {}
    for line, cells in _csv_rows(path, _CURVE_COLUMNS):
        try:
            key = (cells["run_key"], int(cells["idx"]))
            step, value = json.loads(cells["step"]), json.loads(cells["value"])
            if not (_is_number(step) and _is_number(value)):
                raise ValueError(f"step and value must be numbers, got {cells['step']!r}, {cells['value']!r}")
        except ValueError as exc:
            raise FolderError(f"{path} line {line}: {_one_line(exc)}") from None
        if key not in designs:
            raise FolderError(f"{path} line {line}: no design ({key[0]}, {key[1]}) in {RUNS}")
        curve = curves.setdefault((*key, cells["name"]), {"step": [], "cost": []})
        curve["step"].append(step)
        curve["cost"].append(value)
    for (run_key, idx, name), curve in curves.items():
        _add_extra(designs[(run_key, idx)]["extras"], name, curve, path)


def _add_extra(extras: dict, name: str, value, path: Path) -> None:
    if name in extras:
        raise FolderError(f"{path}: extra {name!r} of one design is also in {RUNS} or {REPORT}")
    extras[name] = value


def _one_line(exc: Exception) -> str:
    return " ".join(str(exc).split())


def _check(condition: bool, path: Path, problem: str) -> None:
    if not condition:
        raise FolderError(f"{path}: {problem}")


def _design_of(text: str, designs: dict, path: Path, section: str) -> tuple[str, int]:
    run_key, _, idx = text.rpartition("/")
    _check(idx.isdigit() and (run_key, int(idx)) in designs, path,
           f"{section}: {text!r} is no design in {RUNS} (expected 'run_key/idx')")
    return run_key, int(idx)


def _support(entry, path: Path, where: str) -> np.ndarray | None:
    if entry is None:
        return None
    _check(isinstance(entry, dict) and set(entry) == {"n", "nonzero"}, path,
           f"supports: {where} must be null or {{\"n\": ..., \"nonzero\": [[i, j], ...]}}")
    n, nonzero = entry["n"], entry["nonzero"]
    _check(_is_number(n) and isinstance(n, int) and n > 0, path, f"supports: {where}: n must be a positive int")
    _check(isinstance(nonzero, list) and all(
        isinstance(p, list) and len(p) == 2 and all(isinstance(i, int) and not isinstance(i, bool) and 0 <= i < n
                                                    for i in p) for p in nonzero),
           path, f"supports: {where}: nonzero must be [i, j] pairs with 0 <= i, j < {n}")
    support = np.zeros((n, n), dtype=bool)
    if nonzero:
        support[tuple(np.asarray(nonzero).T)] = True
    return support


def _read_report(path: Path, designs: dict) -> dict:
    """report.json, checked; merges its non-curve extras and null text fields into ``designs``."""
    try:
        document = json.loads(_read_text(path))
    except json.JSONDecodeError as exc:
        raise FolderError(f"{path}: not valid JSON: {exc}") from None
    _check(isinstance(document, dict), path, "expected a JSON object")
    missing = [k for k in ("format", "meta", "members", "superseded", "software") if k not in document]
    _check(not missing, path, f"missing keys {', '.join(missing)}")
    _check(document["format"] == FOLDER_FORMAT, path,
           f"format {document['format']!r}, this version of compare reads format {FOLDER_FORMAT}")
    _check(isinstance(document["meta"], dict), path, "meta must be an object")
    members = document["members"]
    _check(isinstance(members, dict) and all(isinstance(v, list) and all(isinstance(k, str) for k in v)
                                             for v in members.values()),
           path, "members must map each experiment to a list of run keys")
    superseded = document["superseded"]
    _check(_is_number(superseded) and isinstance(superseded, int) and superseded >= 0, path,
           "superseded must be a count (an int >= 0)")
    software = document["software"]
    _check(isinstance(software, list) and all(isinstance(p, list) and len(p) == 2 and all(isinstance(x, str) for x in p)
                                              for p in software),
           path, "software must be a list of [package, version] string pairs")
    software = dict(software)
    sections = {k: document.get(k, {}) for k in ("supports", "drawings", "other_extras", "null_text", "figures")}
    for name, section in sections.items():
        _check(isinstance(section, dict), path, f"{name} must be an object")
    supports = {_design_of(k, designs, path, "supports"): _support(v, path, repr(k))
                for k, v in sections["supports"].items()}
    instances = {canonical_key(row["instance"]) for row in designs.values()}
    for key, entry in sections["drawings"].items():
        _check(key in instances, path, f"drawings: {key!r} is no instance in {RUNS}")
        try:
            InstanceDrawing.from_facts(entry)
        except ValueError as exc:
            raise FolderError(f"{path}: drawings: {_one_line(exc)}") from None
    for text, extras in sections["other_extras"].items():
        key = _design_of(text, designs, path, "other_extras")
        _check(isinstance(extras, dict), path, f"other_extras: {text!r} must be an object")
        for name, value in extras.items():
            _add_extra(designs[key]["extras"], name, value, path)
    for text, names in sections["null_text"].items():
        key = _design_of(text, designs, path, "null_text")
        _check(isinstance(names, list) and set(names) <= set(_TEXT), path,
               f"null_text: {text!r} must list text columns ({', '.join(_TEXT)})")
        for name in names:
            _check(designs[key][name] == "", path, f"null_text: {text!r} says {name} is None, {RUNS} has text")
            designs[key][name] = None
    return {"meta": document["meta"], "members": {k: frozenset(v) for k, v in members.items()},
            "superseded": superseded, "software": software, "supports": supports, "figures": sections["figures"],
            "drawings": sections["drawings"]}


def read_folder(out) -> FolderData:
    """Read a folder written by :func:`write_folder`.

    Parameters
    ----------
    out : str or Path
        The report folder.

    Returns
    -------
    FolderData

    Raises
    ------
    FolderError
        A file is missing or malformed (the one-line message names the file and the problem).
    """
    out = Path(out)
    if not out.is_dir():
        raise FolderError(f"{out}: no such folder")
    missing = [name for name in FOLDER_FILES.values() if not (out / name).is_file()]
    if missing:
        raise FolderError(f"{out}: no {', '.join(missing)} (a report folder that rebuilds itself holds "
                          f"{', '.join(FOLDER_FILES.values())}; rerun `compare run` or `compare report` "
                          "from the store to write them)")
    rows, facts = _read_runs(out / RUNS)
    designs = {(row["run_key"], row["idx"]): row for row in rows}
    report = _read_report(out / REPORT, designs)
    for key, drawing in report.pop("drawings").items():  # old folders keep none: their figure is left out
        facts[key] = {**facts[key], "drawing": drawing}
    _read_curves(out / CURVES, designs)
    return FolderData(records=Records.from_rows(rows, facts), **report)
