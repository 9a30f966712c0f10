"""Your own systems from ``.npz`` files, one instance per file (docs/extending.md).

Spec::

    [instances]
    family = "matrices"
    files = ["systems/*.npz", "chain.npz"]    # paths or globs, relative to the spec file

Each file holds arrays ``A`` (n × n) and ``B`` (n × m) and optionally ``Q``,
``R`` (identity by default), ``state_nodes`` and ``input_nodes`` (the node of
each state and input; one per node by default), ``comm_adj`` (the given
communication graph between nodes, nonzero = node i receives from node j; the
plant graph by default), ``horizon`` (a scalar, 50 by default) and ``x0_cov``
(n × n, the covariance of the initial state, identity by default; ``B1 @ B1.T``
poses an H2 problem whose disturbances enter through ``B1``).

An instance's identity in the store is the SHA-256 of its file's contents, not
its path: editing a file gives new runs, moving or renaming it does not. A file
that cannot be read, misses a key, has keys this family does not know, or
describes a system :meth:`codesign.Instance.from_matrices` rejects (shapes, NaN,
not stabilizable) is a spec error naming the file.
"""

from __future__ import annotations

import glob
import hashlib
import io
from pathlib import Path

import numpy as np

from ..parsing import SpecError, check_keys, typed
from . import Family, register_family

KEYS = {"family", "files"}
REQUIRED = ("A", "B")
OPTIONAL = ("Q", "R", "comm_adj", "horizon", "state_nodes", "input_nodes", "x0_cov")


def _paths(value, base) -> list[Path]:
    patterns = value if isinstance(value, list) else [value]
    if not patterns:
        raise SpecError("instances.files: must not be empty")
    root = Path(base) if base is not None else Path.cwd()
    paths: list[Path] = []
    for i, pattern in enumerate(patterns):
        pattern = typed(f"instances.files[{i}]", pattern, str)
        full = pattern if Path(pattern).is_absolute() else str(root / pattern)
        matches = sorted(glob.glob(full)) if glob.has_magic(full) else [full]
        matches = [Path(m) for m in matches if Path(m).is_file()]
        if not matches:
            raise SpecError(f"instances.files[{i}]: no file matches {pattern!r} (relative to {root})")
        paths += [m.resolve() for m in matches if m.resolve() not in paths]
    return paths


def _read(path: Path) -> tuple[bytes, dict]:
    data = path.read_bytes()
    try:
        with np.load(io.BytesIO(data), allow_pickle=False) as archive:
            arrays = {key: np.asarray(archive[key]) for key in archive.files}
    except Exception as exc:  # any unreadable file is the user's input error, named below
        raise ValueError(f"not a readable .npz file ({type(exc).__name__}: {exc})") from None
    return data, arrays


def _instance(arrays: dict, name: str):
    from codesign import Instance

    missing = [key for key in REQUIRED if key not in arrays]
    if missing:
        raise ValueError(f"missing array(s) {', '.join(missing)} (required: A, B)")
    unknown = sorted(set(arrays) - set(REQUIRED) - set(OPTIONAL))
    if unknown:
        raise ValueError(f"unknown array(s) {', '.join(unknown)} (known: {', '.join(REQUIRED + OPTIONAL)})")
    horizon = 50
    if "horizon" in arrays:
        h = arrays["horizon"]
        if h.shape != () or not np.issubdtype(h.dtype, np.integer):
            raise ValueError(f"horizon must be a scalar integer, got {h!r}")
        horizon = int(h)
    return Instance.from_matrices(arrays["A"], arrays["B"], Q=arrays.get("Q"), R=arrays.get("R"),
                                  comm_adj=arrays.get("comm_adj"), horizon=horizon, name=name,
                                  state_nodes=arrays.get("state_nodes"), input_nodes=arrays.get("input_nodes"),
                                  x0_cov=arrays.get("x0_cov"))


def parse(table: dict, base=None) -> tuple:
    check_keys("instances", table, KEYS)
    if "files" not in table:
        raise SpecError("instances.files: required for family 'matrices' (paths or globs of .npz files)")
    specs, seen = [], {}
    for path in _paths(table["files"], base):
        try:
            data, arrays = _read(path)
            instance = _instance(arrays, path.stem)
        except (ValueError, OSError) as exc:  # InstanceError is a ValueError
            raise SpecError(f"instances.files: {path}: {exc}") from None
        digest = hashlib.sha256(data).hexdigest()
        if digest in seen:
            raise SpecError(f"instances.files: {path} has the same contents as {seen[digest]}")
        seen[digest] = path
        specs.append({"family": "matrices", "name": path.stem, "n": int(instance.nodes),
                      "file": str(path), "sha256": digest})
    return tuple(specs)


def build(spec: dict):
    path = Path(spec["file"])
    data, arrays = _read(path)
    if hashlib.sha256(data).hexdigest() != spec["sha256"]:
        raise ValueError(f"{path} changed after the spec was read; run the experiment again")
    return _instance(arrays, spec.get("name", path.stem))


def identity(spec: dict) -> dict:
    """The file's contents, not its path: a moved file keeps its runs, an edited one gets new ones."""
    return {"family": "matrices", "sha256": spec["sha256"]}


MATRICES = register_family(Family(
    name="matrices",
    summary="your own systems from .npz files (A, B; optional Q, R, comm_adj, horizon, x0_cov), one instance per file",
    parse=parse,
    build=build,
    fields=frozenset({"name", "n"}),
    identity=identity,
))
