"""The result store: one SQLite file, one row per run, keyed by content.

Each finished run is written in a single transaction (its run row and all its
designs), so a run killed mid-write leaves nothing behind and a rerun finds
every completed run. Controllers are stored as ``.npz`` blobs (numpy arrays
only, loaded with ``allow_pickle=False``), never as pickles.

Several ``compare run`` processes may fill one store at once: a process claims
the runs it will compute (one transaction, so no run is claimed twice) and
leaves runs claimed by a live process to it. Claims of a process that died (on
this host: its pid is gone; elsewhere: no heartbeat for :data:`STALE_SECONDS`)
are taken over.
"""

from __future__ import annotations

import functools
import io
import json
import os
import re
import socket
import sqlite3
import time
from pathlib import Path

import numpy as np

from codesign.controllers import controller_from_arrays
from codesign.status import FAILED

from .meta import MetaKind, entries_of, meta_key
from .records import Records, canonical_key, row_problem

__all__ = ["Store", "StoreError", "APPLICATION_ID", "SCHEMA_VERSION"]

_SCHEMA = """
CREATE TABLE IF NOT EXISTS meta (key TEXT PRIMARY KEY, value TEXT NOT NULL);
CREATE TABLE IF NOT EXISTS runs (
    run_key TEXT PRIMARY KEY,
    experiment TEXT NOT NULL,
    instance TEXT NOT NULL,
    method TEXT NOT NULL,
    label TEXT NOT NULL,
    params TEXT NOT NULL,
    version TEXT NOT NULL,
    n_designs INTEGER NOT NULL,
    seconds REAL NOT NULL,
    peak_mb REAL,
    scoring_seconds REAL,
    baseline_mb REAL
);
CREATE TABLE IF NOT EXISTS designs (
    run_key TEXT NOT NULL REFERENCES runs(run_key),
    idx INTEGER NOT NULL,
    method TEXT NOT NULL,
    label TEXT NOT NULL,
    params TEXT NOT NULL,
    cost REAL,
    cost_stderr REAL,
    cost_kind TEXT,
    links INTEGER,
    self_loops INTEGER,
    info_model TEXT,
    status TEXT NOT NULL,
    message TEXT,
    seconds REAL,
    controller_kind TEXT,
    controller BLOB,
    extras TEXT,
    PRIMARY KEY (run_key, idx)
);
CREATE TABLE IF NOT EXISTS claims (
    run_key TEXT PRIMARY KEY,
    owner TEXT NOT NULL,
    host TEXT NOT NULL,
    pid INTEGER NOT NULL,
    heartbeat REAL NOT NULL
);
CREATE TABLE IF NOT EXISTS members (
    experiment TEXT NOT NULL,
    run_key TEXT NOT NULL,
    PRIMARY KEY (experiment, run_key)
);
"""

#: A claim from another host with no heartbeat for this long is taken over.
STALE_SECONDS = 6 * 3600.0

#: SQLite's ``application_id`` of a result store ("GRNN"): what marks a file as one of ours.
APPLICATION_ID = 0x47524E4E
#: SQLite's ``user_version`` of the schema this code writes. 1: the columns of 2 but ``runs.peak_mb``;
#: stores written before the mark existed are recognized by their tables and migrated as version 1.
#: 2: the columns of 3 but ``runs.scoring_seconds`` and ``runs.baseline_mb``.
SCHEMA_VERSION = 3

#: Run columns added after the first schema, with their type: a store of an older version gains the
#: ones it lacks when opened, NULL (unknown) in the runs it already holds.
_LATER_RUN_COLUMNS = {"peak_mb": "REAL", "scoring_seconds": "REAL", "baseline_mb": "REAL"}

_TABLES = {"meta", "runs", "designs", "claims", "members"}
_RUN_COLUMNS = ("run_key", "experiment", "instance", "method", "label", "params", "version", "n_designs", "seconds")
_DESIGN_COLUMNS = ("run_key", "idx", "method", "label", "params", "cost", "cost_stderr", "cost_kind", "links",
                   "self_loops", "info_model", "status", "message", "seconds", "controller_kind", "controller",
                   "extras")


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # pragma: no cover - someone else's live process
        return True
    return True


class StoreError(RuntimeError):
    """The store file is unreadable or not a result store."""


def _read_only_uri(path: Path) -> str:
    """An SQLite URI that opens ``path`` for reading without creating or changing any file.

    ``mode=ro`` alone still creates ``-wal`` and ``-shm`` files beside a database in WAL
    mode (and leaves them there); when no such files exist, no process has it open in
    WAL mode, so ``immutable=1`` (no locks, no side files) reads it safely. Otherwise
    ``mode=ro`` takes the shared lock that keeps a read consistent while another
    ``compare run`` writes.
    """
    uri = f"{path.resolve().as_uri()}?mode=ro"
    try:
        with path.open("rb") as handle:
            header = handle.read(20)
    except OSError:
        return uri  # sqlite3 says why it cannot open it
    wal_mode = header.startswith(b"SQLite format 3\x00") and header[18:19] == b"\x02"
    side_files = any(path.with_name(path.name + suffix).exists() for suffix in ("-wal", "-shm"))
    return uri + "&immutable=1" if wal_mode and not side_files else uri


def _damage(conn: sqlite3.Connection) -> str | None:
    """SQLite's first complaint about the file's pages (``PRAGMA quick_check``), None if it finds none."""
    found = [row[0] for row in conn.execute("PRAGMA quick_check(2)")]
    if found == ["ok"]:
        return None
    lines = [line for text in found for line in text.splitlines() if line.strip() and not line.startswith("***")]
    return lines[0] if lines else "; ".join(found)


def _inspect(path: Path) -> int:
    """The schema version of the store at ``path``, read without writing a byte; StoreError if not a store.

    A file marked with :data:`APPLICATION_ID` gives its ``user_version``; an unmarked one is a
    store only if its tables are exactly a (pre-mark) store's, version 1. Anything else (another
    program's database, a newer store, not SQLite at all, a damaged file) is refused before it is
    opened for writing.
    """
    try:
        conn = sqlite3.connect(_read_only_uri(path), uri=True, timeout=30)
    except sqlite3.Error as exc:
        raise StoreError(_explain(path, exc)) from None
    try:
        app_id = conn.execute("PRAGMA application_id").fetchone()[0]
        version = conn.execute("PRAGMA user_version").fetchone()[0]
        tables = {row[0] for row in conn.execute("SELECT name FROM sqlite_master WHERE type = 'table'")}
        columns = {t: [row[1] for row in conn.execute(f"PRAGMA table_info({t})")] for t in tables & {"runs", "designs"}}
        # Damage (a disk error, a partial copy) is found here, before a writer touches the file:
        # otherwise the first query that reaches a bad page fails after the run has written into it.
        damage = _damage(conn) if app_id == APPLICATION_ID or {"runs", "designs"} <= tables else None
    except sqlite3.DatabaseError as exc:
        raise StoreError(_explain(path, exc)) from None
    finally:
        conn.close()
    untouched = "; it was left untouched"
    if damage is not None:
        raise StoreError(_damaged(path, damage))
    if app_id == APPLICATION_ID:
        if version > SCHEMA_VERSION:
            raise StoreError(f"{path} is a result store of a newer version of this toolkit (schema {version}; "
                             f"this one reads up to {SCHEMA_VERSION}): upgrade grnn-codesign{untouched}")
        return version
    if app_id != 0:
        raise StoreError(f"{path} is another program's SQLite database (application id {app_id:#x}), "
                         f"not a result store{untouched}")
    legacy = (tables and tables <= _TABLES and {"meta", "runs", "designs"} <= tables
              and tuple(columns["runs"][:len(_RUN_COLUMNS)]) == _RUN_COLUMNS
              and tuple(columns["designs"]) == _DESIGN_COLUMNS)
    if not legacy:
        found = ", ".join(sorted(tables)) or "no tables"
        raise StoreError(f"{path} is an SQLite database but not a result store ({found}){untouched}")
    return 1


def _explain(path: Path, exc: sqlite3.Error, *, opening: bool = True) -> str:
    """A one-line reason for an SQLite error on ``path``: locked, unwritable, damaged, or not a store.

    ``opening`` False: the error came from a store already open (the file may have been written).
    """
    text = str(exc)
    if "locked" in text or "busy" in text:
        return f"the result store {path} is locked by another process (still writing after 30 s); try again later"
    if "readonly" in text or "read-only" in text:
        return f"the result store {path} is read-only: {text}"
    if "unable to open" in text:
        folder = path.parent if path.parent != Path("") else Path(".")
        if folder.is_dir() and not os.access(folder, os.W_OK | os.X_OK):
            return f"cannot create the result store {path}: the folder {folder} is not writable"
        return f"cannot open the result store {path}: {text}"
    if "malformed" in text or "corrupt" in text:
        return _damaged(path, text, untouched=opening)
    if not opening:
        return f"the result store {path} cannot be read or written: {text}"
    return f"{path} is not a usable result store: {text}; it was left untouched"


def _damaged(path: Path, problem: str, *, untouched: bool = True) -> str:
    kept = "; it was left untouched" if untouched else ""
    return f"the result store {path} is damaged ({problem}){kept}: restore it from a copy, or give another store"


def _guarded(method):
    """Turn an SQLite error inside a store method into a :class:`StoreError` naming the file.

    A store can be damaged after it was opened (a disk fault, another program writing
    into it); the caller then gets the project's one error type, not ``sqlite3``'s.
    A write that fails is rolled back by its transaction.
    """
    @functools.wraps(method)
    def guarded(self, *args, **kwargs):
        try:
            return method(self, *args, **kwargs)
        except sqlite3.ProgrammingError:  # a misuse of the store (closed, another thread's): a bug, not the file
            raise
        except sqlite3.DatabaseError as exc:
            raise StoreError(_explain(self.path, exc, opening=False)) from None
    return guarded


def _npz(arrays: dict) -> bytes:
    buffer = io.BytesIO()
    np.savez_compressed(buffer, **{k: np.asarray(v) for k, v in arrays.items()})
    return buffer.getvalue()


def _float_or_none(value):
    value = float(value)
    return value if np.isfinite(value) else None


class Store:
    """A SQLite result store.

    A store marks itself (SQLite's ``application_id`` :data:`APPLICATION_ID` and
    ``user_version`` :data:`SCHEMA_VERSION`); opening any other file raises
    :class:`StoreError` before a byte of it is written, and an older store is
    migrated in one transaction.

    Parameters
    ----------
    path : str or Path
        The database file; created (with its folder) if missing or empty.
    create : bool
        False refuses a missing file (readers: ``compare report`` and ``compare export``).
    read_only : bool
        Open the file with SQLite's read-only URI (:func:`_read_only_uri`) and change
        nothing in it: no journal mode, no migration (an older store's missing columns
        read as unknown), no write; what ``compare report`` and ``compare export`` use,
        so that a store's bytes are the same after them. A missing file is refused, and
        the writing methods raise :class:`StoreError`.
    """

    def __init__(self, path, *, create: bool = True, read_only: bool = False):
        self.path = Path(path)
        self.read_only = read_only
        new = not self.path.exists() or (self.path.is_file() and self.path.stat().st_size == 0)
        if new and (read_only or not create):
            raise StoreError(f"no result store at {self.path}")
        version = 0 if new else _inspect(self.path)
        if read_only:
            # Not the read-write connection below: its journal_mode=DELETE alone rewrites a WAL store's
            # header (bytes 18-19 and the change counter), and a migration would write the schema.
            try:
                self._conn = sqlite3.connect(_read_only_uri(self.path), uri=True, timeout=30)
                # A store from before the mark may lack the tables a migration would add: empty ones in
                # this connection's own temporary schema stand in for them (the file is not touched).
                held = {row[0] for row in self._conn.execute("SELECT name FROM sqlite_master WHERE type = 'table'")}
                for statement in _SCHEMA.split(";"):
                    table = re.search(r"CREATE TABLE IF NOT EXISTS (\w+)", statement)
                    if table is not None and table[1] not in held:
                        self._conn.execute(statement.replace("CREATE TABLE", "CREATE TEMP TABLE", 1))
                self._conn.execute("PRAGMA query_only = ON")  # no write at all, to those stand-ins either
            except sqlite3.DatabaseError as exc:
                raise StoreError(_explain(self.path, exc)) from None
            return
        if new:
            self.path.parent.mkdir(parents=True, exist_ok=True)
        try:
            self._conn = sqlite3.connect(self.path, timeout=30)
            self._conn.execute("PRAGMA journal_mode=DELETE")
            self._conn.execute("PRAGMA synchronous=FULL")
            if version < SCHEMA_VERSION:
                self._upgrade(version)
        except sqlite3.DatabaseError as exc:
            raise StoreError(_explain(self.path, exc)) from None

    def _upgrade(self, version: int) -> None:
        """Create the schema (``version`` 0) or migrate an older one, in one transaction: all of it or nothing."""
        with self._conn:
            self._conn.execute("BEGIN IMMEDIATE")
            for statement in _SCHEMA.split(";"):
                if statement.strip():
                    self._conn.execute(statement)
            if version >= 1:
                columns = {row[1] for row in self._conn.execute("PRAGMA table_info(runs)")}
                for name, kind in _LATER_RUN_COLUMNS.items():
                    if name not in columns:
                        self._conn.execute(f"ALTER TABLE runs ADD COLUMN {name} {kind}")
            self._conn.execute(f"PRAGMA application_id = {APPLICATION_ID}")
            self._conn.execute(f"PRAGMA user_version = {SCHEMA_VERSION}")

    def close(self) -> None:
        self._conn.close()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()

    # -- writing ----------------------------------------------------------------
    @_guarded
    def set_meta(self, key: str, value) -> None:
        self.set_metas({key: value})

    @_guarded
    def set_metas(self, entries: dict) -> None:
        """Set several meta entries (key -> JSON value) in one transaction."""
        with self._conn:
            self._conn.executemany("INSERT OR REPLACE INTO meta VALUES (?, ?)",
                                   [(key, json.dumps(value, sort_keys=True)) for key, value in entries.items()])

    def set_instance_facts(self, instance_spec: dict, facts: dict) -> None:
        """Store what a report needs to know about an instance (:func:`compare.run.runner.instance_facts`)."""
        self.set_metas(self.instance_facts_entries([(instance_spec, facts)]))

    @staticmethod
    def instance_facts_entries(items) -> dict:
        """The meta entries of ``(instance spec, facts)`` pairs, for :meth:`set_metas` (several in one transaction)."""
        return {meta_key(MetaKind.INSTANCE, canonical_key(spec)): facts for spec, facts in items}

    def instance_facts(self) -> dict[str, dict]:
        """Instance key (:func:`compare.run.records.canonical_key` of its spec) -> its stored facts."""
        return entries_of(self.meta(), MetaKind.INSTANCE)

    @_guarded
    def set_members(self, experiment: str, keys) -> None:
        """Record which runs make up an experiment now (a run may belong to several).

        Runs an experiment no longer names (their code changed, so their keys did) stay
        stored, and are reused if the code comes back, but are no longer reported.
        """
        with self._conn:
            self._conn.execute("DELETE FROM members WHERE experiment = ?", (experiment,))
            self._conn.executemany("INSERT OR IGNORE INTO members VALUES (?, ?)", [(experiment, k) for k in keys])

    @_guarded
    def claim(self, keys, owner: str) -> list[str]:
        """Claim the runs among ``keys`` that are neither stored nor claimed by a live process.

        Returns the keys now claimed by ``owner``, in order. One immediate
        transaction, so two processes never claim the same run.
        """
        host, pid, now = socket.gethostname(), os.getpid(), time.time()
        with self._conn:
            self._conn.execute("BEGIN IMMEDIATE")
            for key, other_host, other_pid, beat in self._conn.execute(
                    "SELECT run_key, host, pid, heartbeat FROM claims WHERE owner != ?", (owner,)).fetchall():
                dead = not _alive(other_pid) if other_host == host else now - beat > STALE_SECONDS
                if dead:
                    self._conn.execute("DELETE FROM claims WHERE run_key = ?", (key,))
            taken = {row[0] for row in self._conn.execute("SELECT run_key FROM claims WHERE owner != ?", (owner,))}
            taken |= self.done_keys()
            mine = [k for k in dict.fromkeys(keys) if k not in taken]
            self._conn.executemany("INSERT OR REPLACE INTO claims VALUES (?, ?, ?, ?, ?)",
                                   [(k, owner, host, pid, now) for k in mine])
        return mine

    @_guarded
    def claims(self) -> dict[str, tuple[str, str, int]]:
        """Runs claimed and not yet stored: ``run_key -> (owner, host, pid)``."""
        return {k: (o, h, p) for k, o, h, p in self._conn.execute("SELECT run_key, owner, host, pid FROM claims")}

    @_guarded
    def release(self, owner: str) -> None:
        """Drop ``owner``'s remaining claims (runs it did not finish)."""
        with self._conn:
            self._conn.execute("DELETE FROM claims WHERE owner = ?", (owner,))

    @_guarded
    def add_run(self, run, designs, *, experiment: str, seconds: float, peak_mb: float | None = None,
                scoring_seconds: float | None = None, baseline_mb: float | None = None,
                owner: str | None = None) -> bool:
        """Store a finished run and its designs atomically; False if it was already stored.

        ``seconds`` is the run's wall time, ``scoring_seconds`` the part of it spent scoring
        its designs, ``peak_mb`` and ``baseline_mb`` its process's peak resident memory and
        the resident memory it started from, in MB (each None if unknown; see
        :class:`compare.run.execution.RunResult`). The run's claim goes in the same
        transaction; ``owner``'s other claims get a heartbeat.
        """
        rows = []
        for idx, design in enumerate(designs):
            record = design.to_record()
            controller = design.controller
            blob = _npz(controller.arrays()) if controller is not None and hasattr(controller, "arrays") else None
            rows.append(
                (
                    run.key, idx, record["method"], run.label, record["params"],
                    _float_or_none(record["cost"]), _float_or_none(record["cost_stderr"]), record["cost_kind"],
                    record["links"], record["self_loops"], record["info_model"], record["status"],
                    record["message"], record["seconds"], record["controller"], blob, record["extras"],
                )
            )
        with self._conn:
            cursor = self._conn.execute(
                "INSERT OR IGNORE INTO runs (run_key, experiment, instance, method, label, params, version, "
                "n_designs, seconds, peak_mb, scoring_seconds, baseline_mb) "
                "VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?)",
                (
                    run.key, experiment, json.dumps(run.instance, sort_keys=True), run.method, run.label,
                    json.dumps(run.params, sort_keys=True), run.fingerprint, len(rows), float(seconds),
                    *(None if value is None else float(value) for value in (peak_mb, scoring_seconds, baseline_mb)),
                ),
            )
            if cursor.rowcount == 0:
                return False
            self._conn.executemany(f"INSERT INTO designs VALUES ({', '.join('?' * 17)})", rows)
            self._conn.execute("DELETE FROM claims WHERE run_key = ?", (run.key,))
            if owner is not None:
                self._conn.execute("UPDATE claims SET heartbeat = ? WHERE owner = ?", (time.time(), owner))
        return True

    @_guarded
    def timed_out(self) -> dict[str, float]:
        """Stored runs that stopped at their time limit: ``run_key -> limit`` in seconds."""
        out = {}
        for key, extras in self._conn.execute(
                "SELECT run_key, extras FROM designs WHERE status = ? AND extras LIKE '%timeout_s%'", (FAILED,)):
            limit = json.loads(extras).get("timeout_s") if extras else None
            if limit is not None:
                out[key] = float(limit)
        return out

    @_guarded
    def forget(self, keys) -> int:
        """Delete stored runs and their designs (one transaction); returns how many were stored.

        Used for runs stored as stopped at a time limit when the experiment now allows them more.
        """
        keys = list(keys)
        with self._conn:
            self._conn.executemany("DELETE FROM designs WHERE run_key = ?", [(k,) for k in keys])
            removed = sum(self._conn.execute("DELETE FROM runs WHERE run_key = ?", (k,)).rowcount for k in keys)
        return removed

    @_guarded
    def relabel(self, labels: dict[str, str]) -> int:
        """Set the legend label of stored runs (``run_key -> label``); returns how many changed.

        Labels are presentation, not part of a run's content key, so a spec can rename
        a method without recomputing it.
        """
        changed = 0
        with self._conn:
            for key, label in labels.items():
                cur = self._conn.execute("UPDATE runs SET label = ? WHERE run_key = ? AND label != ?", (label, key, label))
                if cur.rowcount:
                    self._conn.execute("UPDATE designs SET label = ? WHERE run_key = ?", (label, key))
                    changed += 1
        return changed

    @_guarded
    def redescribe(self, instances: dict[str, dict]) -> int:
        """Set the instance spec stored with runs (``run_key -> spec``); returns how many changed.

        A run's key hashes its family's identity of the instance, not always all of the
        spec: a ``matrices`` file renamed or moved keeps its runs (their key is the file's
        contents), and this gives them its new ``name`` and ``file``, so that reports,
        exports and ``where`` agree on the name.
        """
        rows = [(json.dumps(spec, sort_keys=True), key) for key, spec in instances.items()]
        with self._conn:
            before = self._conn.total_changes
            self._conn.executemany("UPDATE runs SET instance = ?1 WHERE run_key = ?2 AND instance != ?1", rows)
            return self._conn.total_changes - before

    # -- reading ----------------------------------------------------------------
    @_guarded
    def done_keys(self) -> set[str]:
        return {row[0] for row in self._conn.execute("SELECT run_key FROM runs")}

    @_guarded
    def meta(self) -> dict:
        return {k: json.loads(v) for k, v in self._conn.execute("SELECT key, value FROM meta")}

    @_guarded
    def members(self) -> dict[str, set]:
        """Experiment name -> the run keys that make it up."""
        out: dict[str, set] = {}
        for experiment, key in self._conn.execute("SELECT experiment, run_key FROM members"):
            out.setdefault(experiment, set()).add(key)
        return out

    @_guarded
    def __len__(self) -> int:
        return self._conn.execute("SELECT COUNT(*) FROM runs").fetchone()[0]

    @_guarded
    def superseded(self) -> int:
        """Stored runs that no experiment names any more (made by code that has changed since)."""
        return self._conn.execute(
            "SELECT COUNT(*) FROM runs WHERE EXISTS (SELECT 1 FROM members) "
            "AND run_key NOT IN (SELECT run_key FROM members)").fetchone()[0]

    @_guarded
    def records(self) -> Records:
        """Every current design as typed, read-only records (no controller): see :mod:`compare.run.records`.

        Current means named by an experiment's latest ``compare run`` (see
        :meth:`set_members`); a store without membership records gives every
        design. Each design's :class:`~compare.run.records.InstanceRecord` carries the
        instance facts the runner stored; they are None for an instance the runner
        could not build, and in stores written before facts were recorded (reports
        then draw without them; nothing is rebuilt).
        """
        # An older store opened read-only was not migrated: the run columns it lacks read as unknown.
        held = {row[1] for row in self._conn.execute("PRAGMA table_info(runs)")}
        later = ", ".join(f"r.{name}" if name in held else f"NULL AS {name}" for name in _LATER_RUN_COLUMNS)
        query = f"""
            SELECT d.run_key, d.idx, r.experiment, r.instance, d.method, d.label, d.params, d.cost,
                   d.cost_stderr, d.cost_kind, d.links, d.self_loops, d.info_model, d.status, d.message,
                   d.seconds, d.controller_kind, d.extras, r.version, r.seconds, r.n_designs, {later}
            FROM designs d JOIN runs r USING (run_key)
            WHERE NOT EXISTS (SELECT 1 FROM members) OR d.run_key IN (SELECT run_key FROM members)
            ORDER BY r.instance, d.label, d.run_key, d.idx
        """
        cols = [
            "run_key", "idx", "experiment", "instance", "method", "label", "params", "cost", "cost_stderr",
            "cost_kind", "links", "self_loops", "info_model", "status", "message", "seconds",
            "controller_kind", "extras", "fingerprint", "run_seconds", "run_designs", "run_peak_mb",
            "run_scoring_seconds", "run_baseline_mb",
        ]
        rows = []
        for row in self._conn.execute(query):
            record = dict(zip(cols, row))
            problem = row_problem(record)
            if problem is not None:
                raise StoreError(f"the result store {self.path} holds a design no method can make "
                                 f"({record['run_key']}, {record['idx']}): {problem}")
            for key in ("instance", "params", "extras"):
                record[key] = json.loads(record[key]) if record[key] else {}
            rows.append(record)
        return Records.from_rows(rows, self.instance_facts())

    @_guarded
    def controller(self, run_key: str, idx: int = 0):
        """Rebuild a stored controller (None if the design had none)."""
        row = self._conn.execute(
            "SELECT controller_kind, controller FROM designs WHERE run_key = ? AND idx = ?", (run_key, idx)
        ).fetchone()
        if row is None:
            raise KeyError(f"no design ({run_key!r}, {idx}) in {self.path}")
        kind, blob = row
        if blob is None:
            return None
        with np.load(io.BytesIO(blob), allow_pickle=False) as data:
            arrays = {k: data[k] for k in data.files}
        return controller_from_arrays(kind, arrays)

    def to_pandas(self):
        """Every current design as a pandas DataFrame, one row per design (as ``compare export`` writes).

        Hyperparameters (``gamma``, ``beta``, ...) and instance fields (``family``,
        ``n``, ``a_norm``, ``seed``, ...) are columns of their own; see
        :func:`compare.run.export.designs_frame` for every column and its type. Needs
        pandas, from the optional extra: ``pip install -e ".[analysis]"``;
        without it, raises :class:`compare.run.export.MissingExtra` (an ImportError).
        """
        from .export import designs_frame

        return designs_frame(self.records(), self.members())
