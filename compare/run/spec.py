"""Experiment specs: TOML files parsed into validated dataclasses.

A spec names the instances (family, sizes, a_norms, seeds), the methods with
their hyperparameters and grids, and evaluation settings. It expands into
:class:`Run` objects, one per (instance, method entry, grid point)::

    name = "quick"               # a folder name (results/quick): letters, digits, _, - and ., not leading
    description = "..."
    plugins = ["my_methods", "more_methods.py"]   # optional: modules registering methods (top level,
                                                  # before any [table], or TOML reads it as a table key)
    max_instances = 50000        # optional (top level): the most instances planned, MAX_INSTANCES by default

    [instances]
    family = "paper"
    n = [20]
    a_norms = [0.995, 1.05]
    seeds = 10                   # seeds 0..9, or an explicit list [0, 4, 7]

    [report]
    sections = ["table1", "training_curves"]       # optional report sections this experiment asks for
    pairs = [["GRNN-Sparse", "Sparse l1 ADMM"]]     # optional paired comparisons (labels or method names)
    ladder = { budgets = [1, 2, 5], methods = ["sparse_admm", "sls"], near = 5.0, claim = "..." }
                                 # optional: the answer opens with each method's best cost within these link
                                 # budgets per system, and whether the first budget comes within near % of LQR

    [evaluation]
    validation_size = 2000       # the default: codesign.evaluation.VALIDATION_SIZE
    noise_std = 0.0

    [[methods]]
    method = "lqr"

    [[methods]]
    method = "decentralized"
    label = "Decentralized"
    params = { start = "lqr_diagonal" }
    grid = { }                   # lists of values, expanded as a cartesian product
    where = { a_norm = [1.05] }  # optional: only on instances with these field values
    timeout = 600                # optional: seconds per run before its worker is stopped (the run is
                                 # recorded failed); a top-level `timeout` sets it for every entry

    [[methods]]
    method = "my_methods:trunc10"   # a plain function f(instance, *, ...) in a module or a .py file
"""

from __future__ import annotations

import hashlib
import itertools
import json
import math
import os
import re
import sys
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib

from .families import UnknownFamilyError, get_family
from .fingerprint import fingerprint
from .parsing import SpecError, check_keys, typed
from .plugins import PluginError, load_plugins, parse_plugin
from .registry import UnknownMethodError, get_method

__all__ = [
    "SpecError",
    "InstanceSpec",
    "MethodSpec",
    "EvaluationSpec",
    "ExperimentSpec",
    "Run",
    "load_spec",
    "parse_spec",
    "preset_names",
    "SECTIONS",
]

#: Report sections an experiment may ask for (``[report] sections``).
SECTIONS = ("table1", "training_curves", "compute")

#: An experiment's name is a folder name (``results/<name>``): letters, digits, ``_``, ``-`` and
#: ``.``, not leading, so that it can never climb out of ``results/`` or hide there.
_NAME = re.compile(r"[\w-][\w.-]*")

#: The size guard's estimate of one run's peak memory, in dense float64 matrices of the
#: instance's state dimension n: the instance's A, B, Q, R, P and its two graphs (7), and
#: the cheapest method's work, centralized LQR's Riccati solve (scipy's
#: ``solve_discrete_are``: a 3n x 3n matrix pencil and its QZ factors, about 34), rounded up.
#: Instances whose estimate exceeds the machine's memory are refused when a spec is loaded.
DENSE_MATRICES = 48

#: The size guard's estimate of scoring a simulated design (a learned controller's), in float64
#: numbers per state of the instance and per validation draw: the draws themselves (validation_size
#: x n), their copy in the rollout, the rollout's blocks and what the control-variate regression
#: adds. Measured with tracemalloc while ``codesign.scoring.evaluate`` scored a GRNN design: 6.8-7.8
#: per state and draw at n = 20 (80,000 and 20,000 draws), 22.9 at n = 100 (where its 1500
#: quadratic features add 15 per state); 7 is about the least of these, so that what is refused
#: could not have fit. Specs whose estimate exceeds the machine's memory are refused when loaded.
VALIDATION_NUMBERS = 7

#: The largest ``timeout`` a spec may give, in seconds (about 116 days). A longer one is refused
#: when the spec is loaded rather than read as "no limit": a limit no run can reach is a typo or a
#: unit mix-up (milliseconds), and past about 9.2e9 s the operating system's wait cannot even hold
#: it (Python's OverflowError "timestamp too large"). Leaving ``timeout`` out means no limit.
MAX_TIMEOUT = 1e7

#: The most instances an experiment plans unless its spec sets ``max_instances``: planning builds
#: each instance once in the main process (about 3-4 ms each at small sizes) and stores about 1 KB
#: of facts for it, so 50,000 take about 3 minutes and 50 MB before the first run.
MAX_INSTANCES = 50_000


@dataclass(frozen=True)
class InstanceSpec:
    """Which instances to build: the families named and one instance spec (a JSON-able dict) per instance.

    The family (:mod:`compare.run.families`) parses the spec's ``[instances]`` table
    into these and builds each :class:`codesign.Instance` where a run executes.
    ``families`` names them in order: several when ``[[instances]]`` (a list of
    tables) joins several families in one experiment.
    """

    families: tuple = ("paper",)
    specs: tuple = ()

    def expand(self) -> list[dict]:
        """The instance specs, one dict per instance (``"family"`` included)."""
        return [dict(spec) for spec in self.specs]


@dataclass(frozen=True)
class MethodSpec:
    """One ``[[methods]]`` entry: a registered method, its label, fixed params and grid.

    ``where`` restricts the entry to instances whose spec fields take the listed
    values, e.g. ``{"a_norm": [1.05]}`` for a grid that suits one family only.
    """

    method: str
    label: str
    params: dict = field(default_factory=dict)
    grid: dict = field(default_factory=dict)
    where: dict = field(default_factory=dict)
    timeout: float | None = None
    #: Entries (method names or labels) whose stored designs' graphs this entry refits, planned after
    #: they are stored (:mod:`compare.run.refits`); empty for an ordinary entry.
    sources: tuple = ()
    #: With ``sources``: per instance, source and budget, only the graph of the source's cheapest design within it.
    budgets: tuple = ()

    def applies_to(self, instance: dict) -> bool:
        return all(instance.get(key) in values for key, values in self.where.items())

    def expand(self) -> list[dict]:
        """Parameter dicts for every grid point (fixed params overlaid by grid values)."""
        if not self.grid:
            return [dict(self.params)]
        keys = list(self.grid)
        return [dict(self.params, **dict(zip(keys, values))) for values in itertools.product(*self.grid.values())]


@dataclass(frozen=True)
class EvaluationSpec:
    """How designs are scored beyond their exact cost.

    ``noise_std > 0`` adds a robustness score: each design's cost under process
    noise ``w(t) ~ N(0, noise_std^2 I)`` (exact for static gains, simulated on
    ``validation_size`` draws otherwise), stored in its extras as ``noise_cost``.
    """

    # codesign.evaluation.VALIDATION_SIZE (not imported: the CLI stays light), the draws the
    # GRNN and GCNN score themselves on, so the harness needs no second rollout.
    validation_size: int = 2000
    noise_std: float = 0.0


@dataclass(frozen=True)
class Run:
    """One unit of work: a method with fixed hyperparameters on one instance."""

    instance: dict
    method: str
    label: str
    params: dict
    evaluation: EvaluationSpec
    fingerprint: str
    #: Seconds the run may take before its worker is stopped (None: no limit); not part of the key.
    timeout: float | None = None

    @property
    def key(self) -> str:
        """Content hash of (instance spec, method, hyperparameters, evaluation, code fingerprint).

        Keys are sorted before hashing, so the order of keys in a spec never changes a key.
        """
        payload = {
            "instance": get_family(self.instance["family"]).identity(self.instance),
            "method": self.method,
            "params": self.params,
            "evaluation": {"noise_std": self.evaluation.noise_std, "validation_size": self.evaluation.validation_size},
            "fingerprint": self.fingerprint,
        }
        text = json.dumps(payload, sort_keys=True, separators=(",", ":"))
        return hashlib.sha256(text.encode()).hexdigest()[:32]


@dataclass(frozen=True)
class ExperimentSpec:
    """A parsed, validated experiment."""

    name: str
    description: str
    instances: InstanceSpec
    methods: tuple[MethodSpec, ...]
    evaluation: EvaluationSpec
    source: str = ""
    plugins: tuple = ()
    sections: tuple = ()
    pairs: tuple = ()
    ladder: dict | None = None

    def runs(self) -> list[Run]:
        """Every run of the experiment, instance-major, keyed with its method's code fingerprint.

        Entries with ``sources`` are not among them: their runs depend on stored designs
        (:func:`compare.run.refits.refit_runs` plans them once those are stored).
        """
        load_plugins(self.plugins)
        prints = {m.method: fingerprint(get_method(m.method)) for m in self.methods}
        return [
            Run(instance, m.method, m.label, params, self.evaluation, prints[m.method], m.timeout)
            for instance in self.instances.expand()
            for m in self.methods
            if not m.sources and m.applies_to(instance)
            for params in m.expand()
        ]


def preset_names() -> list[str]:
    """Names of the presets shipped inside the package."""
    folder = resources.files("compare.run") / "presets"
    return sorted(p.name[:-5] for p in folder.iterdir() if p.name.endswith(".toml"))


def load_spec(name_or_path: str | Path, *, plugins=()) -> ExperimentSpec:
    """Load a preset by name (``"quick"``) or a spec from a TOML file path.

    ``plugins`` adds plug-in modules or files (as ``compare run --plugin``) to the spec's own.
    """
    text_path = Path(name_or_path)
    # A folder named like a preset (the repository's benchmarks/, say) does not hide the preset.
    preset = text_path.is_dir() and str(name_or_path) in preset_names()
    if not preset and (text_path.suffix == ".toml" or text_path.exists()):
        if not text_path.is_file():
            raise SpecError(f"spec file not found: {text_path}")
        text = _read_text(text_path)
        default_name = text_path.stem
        base = text_path.resolve().parent
    else:
        name = str(name_or_path)
        if name not in preset_names():
            raise SpecError(f"unknown preset {name!r}; presets: {', '.join(preset_names())} (or give a .toml file)")
        text = (resources.files("compare.run") / "presets" / f"{name}.toml").read_text()
        default_name = name
        base = None
    return parse_spec(text, default_name=default_name, base=base, plugins=plugins)


def _read_text(path: Path) -> str:
    try:
        data = path.read_bytes()
    except OSError as exc:
        raise SpecError(f"cannot read spec file {path}: {exc.strerror or exc}") from None
    try:
        # utf-8-sig: Windows editors (Notepad, "UTF-8 with BOM") start the file with a byte-order mark.
        text = data.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        raise SpecError(f"{path} is not a text TOML file (byte 0x{data[exc.start]:02x} at offset {exc.start} "
                        "is not UTF-8)") from None
    if "\x00" in text:  # valid UTF-8, but binary all the same
        raise SpecError(f"{path} is not a text TOML file (a NUL byte at offset {data.index(0)})")
    return text


def parse_spec(text: str, *, default_name: str = "experiment", base: str | Path | None = None,
               plugins=()) -> ExperimentSpec:
    """Parse and validate TOML text into an :class:`ExperimentSpec`.

    ``base`` is the folder that relative plug-in paths are resolved against (the
    spec file's folder; by default the working folder); ``plugins`` are extra
    plug-in references imported before the methods are looked up.
    """
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise SpecError(f"spec is not valid TOML: {exc}") from None
    check_keys("spec", data, {"name", "description", "instances", "methods", "evaluation", "plugins", "report",
                              "timeout", "max_instances"})
    refs = [("--plugin", ref) for ref in plugins]
    raw_plugins = data.get("plugins", [])
    if not isinstance(raw_plugins, list):
        raise SpecError(f"plugins: expected a list of module names or .py files, got {raw_plugins!r}")
    refs += [(f"plugins[{i}]", typed(f"plugins[{i}]", ref, str)) for i, ref in enumerate(raw_plugins)]
    loaded = []
    for where, ref in refs:
        try:
            plugin = parse_plugin(ref, base=base if where != "--plugin" else None)
            load_plugins([plugin])
        except PluginError as exc:
            raise SpecError(f"{where}: {exc}") from None
        loaded.append(plugin)
    report = typed("report", data.get("report", {}), dict)
    sections, pairs = _parse_report(report)
    ladder = parse_ladder(report.get("ladder"))
    name = _check_name(typed("name", data.get("name", default_name), str), given="name" in data)
    description = typed("description", data.get("description", ""), str)
    if "instances" not in data:
        raise SpecError("spec: missing [instances] table")
    limit = typed("max_instances", data.get("max_instances", MAX_INSTANCES), int)
    if limit < 1:
        raise SpecError(f"max_instances: must be >= 1, got {limit}")
    instances = _parse_instances(typed("instances", data["instances"], (dict, list)), base,
                                 (limit, "max_instances" in data))
    evaluation = _parse_evaluation(typed("evaluation", data.get("evaluation", {}), dict))
    _check_validation_memory(evaluation, instances)
    raw_methods = typed("methods", data.get("methods", []), list)
    if not raw_methods:
        raise SpecError("methods: the spec needs at least one [[methods]] entry")
    fields = {"family"}.union(*(get_family(name).fields for name in instances.families))
    timeout = _parse_timeout("timeout", data.get("timeout"))
    methods = tuple(_parse_method(i, entry, base, loaded, fields, timeout) for i, entry in enumerate(raw_methods))
    _check_where(methods, instances.expand(), name)
    _check_sources(methods)
    _check_pairs(pairs, methods)
    if ladder is not None:
        _check_pairs((tuple(ladder["methods"]),), methods, where="report.ladder.methods")
    return ExperimentSpec(name, description, instances, methods, evaluation, text, tuple(loaded), sections, pairs,
                          ladder)


def _check_name(name: str, *, given: bool) -> str:
    """The experiment's name, which the CLI makes a folder under ``results/``: a plain folder name only."""
    if _NAME.fullmatch(name):
        return name
    rule = "a plain folder name (letters, digits, '_', '-' and '.', not leading)"
    if given:
        raise SpecError(f"name: must be {rule}, got {name!r}")
    raise SpecError(f"name: the spec file's name {name!r} is not {rule}; set name = \"...\" in the spec")


def _values_text(values) -> str:
    """The distinct values, as Python writes them, numbers in order (by repr: a value may not hash)."""
    distinct = {repr(v): v for v in values}

    def order(text):
        value = distinct[text]
        number = isinstance(value, (int, float)) and not isinstance(value, bool) and value == value
        return (0, value, "") if number else (1, 0, text)

    return ", ".join(sorted(distinct, key=order))


def _check_where(methods: tuple, instances: list[dict], experiment: str) -> None:
    """Every method entry's ``where`` selects at least one instance; else name the key and what it takes.

    A value of the wrong type (``["0.995"]``, a string where the field holds numbers) matches
    nothing, and the entry would otherwise be dropped without a word.
    """
    for i, m in enumerate(methods):
        if not m.where or any(m.applies_to(instance) for instance in instances):
            continue
        given = " and ".join(f"{key} = {values!r}" for key, values in m.where.items())
        taken = {key: [inst[key] for inst in instances if key in inst] for key in m.where}
        unmatched = [key for key, values in m.where.items() if not any(v in values for v in taken[key])]
        # Name the key that matches nothing; if each matches some instance, it is their combination.
        shown = unmatched or list(m.where)
        takes = "; ".join(f"{key} takes {_values_text(taken[key])}" if taken[key] else f"no instance has {key}"
                          for key in shown)
        raise SpecError(f"methods[{i}].where: {given} matches no instance of experiment {experiment}; {takes}")


def _check_pairs(pairs: tuple, methods: tuple, where: str | None = None) -> None:
    """Every label a ``[report] pairs`` entry (or the list ``where`` names) names is a method entry's label or
    method name."""
    known = list(dict.fromkeys([m.label for m in methods] + [m.method for m in methods]))
    for i, pair in enumerate(pairs):
        for x in pair:
            if x not in known:
                raise SpecError(f"{where or f'report.pairs[{i}]'}: {x!r} is no method entry's label or method "
                                f"name (known: {', '.join(repr(k) for k in known)})")


#: ``[report] ladder``'s defaults: link budgets, and the excess over LQR (per cent) that counts as near it.
LADDER_BUDGETS = (1, 2, 5)
LADDER_NEAR = 5.0


def parse_ladder(table) -> dict | None:
    """``[report] ladder`` checked, with its defaults filled in (None where the spec has none).

    ``budgets``: link budgets (ints >= 0, increasing; default 1, 2, 5); ``methods``: labels
    or method names (default: every method entry's); ``near``: the excess over LQR, in per
    cent, within which a design counts as close to it (default 5); ``claim``: the claim checked,
    in words (optional). :mod:`compare.report.answer` reads it from the stored spec text.
    """
    if table is None:
        return None
    if not isinstance(table, dict):
        raise SpecError(f"report.ladder: expected a table (budgets, methods, near, claim), got {table!r}")
    check_keys("report.ladder", table, {"budgets", "methods", "near", "claim"})
    budgets = table.get("budgets", list(LADDER_BUDGETS))
    if not (isinstance(budgets, list) and budgets and all(isinstance(b, int) and not isinstance(b, bool) and b >= 0
                                                           for b in budgets)):
        raise SpecError(f"report.ladder.budgets: expected a non-empty list of link counts >= 0, got {budgets!r}")
    if sorted(set(budgets)) != budgets:
        raise SpecError(f"report.ladder.budgets: must increase, got {budgets!r}")
    methods = table.get("methods", [])
    if not (isinstance(methods, list) and all(isinstance(x, str) and x for x in methods)):
        raise SpecError(f"report.ladder.methods: expected a list of method labels or names, got {methods!r}")
    near = table.get("near", LADDER_NEAR)
    if isinstance(near, bool) or not isinstance(near, (int, float)) or not 0 < near < math.inf:
        raise SpecError(f"report.ladder.near: expected a percentage > 0, got {near!r}")
    claim = typed("report.ladder.claim", table.get("claim", ""), str)
    return {"budgets": list(budgets), "methods": list(methods), "near": float(near), "claim": claim}


def _parse_report(table: dict) -> tuple[tuple, tuple]:
    check_keys("report", table, {"sections", "pairs", "ladder"})
    sections = table.get("sections", [])
    if not isinstance(sections, list):
        raise SpecError(f"report.sections: expected a list, got {sections!r}")
    for i, name in enumerate(sections):
        if name not in SECTIONS:
            raise SpecError(f"report.sections[{i}]: unknown section {name!r} (known: {', '.join(SECTIONS)})")
    pairs = table.get("pairs", [])
    if not isinstance(pairs, list):
        raise SpecError(f"report.pairs: expected a list of [first, second] pairs, got {pairs!r}")
    for i, pair in enumerate(pairs):
        if not (isinstance(pair, list) and len(pair) == 2 and all(isinstance(x, str) and x for x in pair)):
            raise SpecError(f"report.pairs[{i}]: expected [first, second] (method labels or names), got {pair!r}")
    return tuple(sections), tuple(tuple(pair) for pair in pairs)


def _parse_instances(table, base, limit: tuple = (MAX_INSTANCES, False)) -> InstanceSpec:
    """One ``[instances]`` table, or a list of them (``[[instances]]``: several families).

    ``limit`` is the most instances allowed and whether the spec set it (:func:`_check_count`).
    """
    tables = [table] if isinstance(table, dict) else table
    if not tables:
        raise SpecError("instances: the list of [[instances]] tables is empty")
    names, specs = [], []
    for i, entry in enumerate(tables):
        where = "instances" if isinstance(table, dict) else f"instances[{i}]"
        entry = typed(where, entry, dict)
        name = typed(f"{where}.family", entry.get("family", "paper"), str)
        try:
            family = get_family(name)
        except UnknownFamilyError as exc:
            raise SpecError(f"{where}.family: {exc}") from None
        names.append(name)
        seeds = entry.get("seeds")
        if isinstance(seeds, int) and not isinstance(seeds, bool):
            # A seed count is checked before the family lists its instances: 1e8 seeds would
            # exhaust memory listing them before the count below could refuse them.
            _check_count(where, len(specs) + seeds, *limit, at_least=True)
        parsed = family.parse(entry, base)
        _check_count(where, len(specs) + len(parsed), *limit)
        _check_memory(where, family, parsed)
        specs.extend(parsed)
    return InstanceSpec(families=tuple(dict.fromkeys(names)), specs=tuple(specs))


def _check_count(where: str, count: int, limit: int, given: bool, *, at_least: bool = False) -> None:
    """Refuse more instances than ``limit`` before any is built (planning builds each one, see :data:`MAX_INSTANCES`).

    ``at_least``: ``count`` is a lower bound (a seed count, before the other keys multiply it).
    """
    if count <= limit:
        return
    said = f"at least {count}" if at_least else f"{count}"
    if given:
        raise SpecError(f"{where}: {said} instances, more than max_instances = {limit}; raise max_instances "
                        "(a top-level key) to plan them all")
    raise SpecError(f"{where}: {said} instances, more than the {limit} an experiment plans by default (each is "
                    f"built once while planning, about 3 ms and 1 KB of store each); set max_instances = "
                    f"{'at least ' * at_least}{count} at the top of the spec to plan them all")


def _machine_memory() -> int | None:
    """This machine's physical memory in bytes, None where it cannot be told."""
    try:
        return os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")
    except (AttributeError, ValueError, OSError):  # not POSIX
        try:
            import psutil
        except ImportError:
            return None
        return int(psutil.virtual_memory().total)


def _bytes_text(size: float) -> str:
    for unit in ("B", "KiB", "MiB", "GiB", "TiB"):
        if size < 1024 or unit == "TiB":
            return f"{size:.3g} {unit}" if unit != "B" else f"{size:.0f} B"
        size /= 1024


def _size_text(spec: dict, states: int) -> str:
    """"n = 20", or "n = 39 (78 states)" where nodes have several states."""
    nodes = spec.get("n", states)
    return f"n = {nodes}" + (f" ({states} states)" if states != nodes else "")


def _check_memory(where: str, family, specs, memory: int | None = None) -> None:
    """Refuse instances whose run would not fit this machine's memory (:data:`DENSE_MATRICES` estimate)."""
    memory = _machine_memory() if memory is None else memory
    if not memory:
        return
    largest_states = math.isqrt(memory // (DENSE_MATRICES * 8))
    for spec in specs:
        states = family.states(spec)
        if not isinstance(states, int) or states <= largest_states:
            continue
        nodes = spec.get("n", states)
        need = DENSE_MATRICES * 8 * states ** 2
        raise SpecError(
            f"{where}.n: {_size_text(spec, states)} needs about {_bytes_text(need)} per run, more than this machine's "
            f"{_bytes_text(memory)} of memory (estimate: {DENSE_MATRICES} dense {states} x {states} float64 "
            f"matrices, the instance and centralized LQR's Riccati solve); the largest n that fits is "
            f"{largest_states * nodes // states}")


def _check_validation_memory(evaluation: EvaluationSpec, instances: InstanceSpec, memory: int | None = None) -> None:
    """Refuse a ``validation_size`` whose draws would not fit this machine's memory (:data:`VALIDATION_NUMBERS`).

    Every simulated cost is scored on ``validation_size`` draws of the instance's states,
    drawn at once: 10^9 draws of 20 states is a 149 GiB array, which a run would otherwise
    try to allocate only after its training, and store as a ``MemoryError``.
    """
    memory = _machine_memory() if memory is None else memory
    if not memory:
        return
    sizes = [(get_family(spec["family"]).states(spec), spec) for spec in instances.specs]
    sizes = [(states, spec) for states, spec in sizes if isinstance(states, int) and states > 0]
    if not sizes:
        return
    states, spec = max(sizes, key=lambda item: item[0])
    draws = evaluation.validation_size
    need = VALIDATION_NUMBERS * 8 * states * draws
    if need <= memory:
        return
    raise SpecError(
        f"evaluation.validation_size: {draws} draws at {_size_text(spec, states)} need about {_bytes_text(need)} to score a "
        f"simulated design, more than this machine's {_bytes_text(memory)} of memory (estimate: "
        f"{VALIDATION_NUMBERS} float64 numbers per state and draw, the draws and their rollout); the largest "
        f"validation_size that fits is {memory // (VALIDATION_NUMBERS * 8 * states)}")


def _parse_evaluation(table: dict) -> EvaluationSpec:
    check_keys("evaluation", table, {"validation_size", "noise_std"})
    size = typed("evaluation.validation_size", table.get("validation_size", EvaluationSpec.validation_size), int)
    noise = typed("evaluation.noise_std", table.get("noise_std", 0.0), float)
    if size < 2:
        raise SpecError(f"evaluation.validation_size: must be >= 2, got {size}")
    if noise < 0:
        raise SpecError(f"evaluation.noise_std: must be >= 0, got {noise}")
    return EvaluationSpec(size, noise)


def _parse_timeout(where: str, value) -> float | None:
    """A time limit in seconds (a positive finite number up to :data:`MAX_TIMEOUT`), or None for none."""
    if value is None:
        return None
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value) or value <= 0:
        raise SpecError(f"{where}: must be a positive number of seconds, got {value!r}")
    if value > MAX_TIMEOUT:
        raise SpecError(f"{where}: {value:g} s is more than the largest time limit, {MAX_TIMEOUT:g} s "
                        f"({MAX_TIMEOUT / 86400:.0f} days); leave timeout out for no limit")
    return float(value)


def _check_together(where: str, method, params: dict, grid: dict) -> None:
    """Every grid point's hyperparameters checked together (the method's own ``check``), before any run.

    Each value is checked alone above; a method may also refuse values that do not go
    together (the GRNN's warm start without its per-node readout), which would otherwise
    be found only when a run starts, and stored as a ``failed`` run that no rerun retries.
    """
    if getattr(method, "check", None) is None:
        return
    for point in MethodSpec(method.name, method.label, dict(params), dict(grid)).expand():
        shown = ", ".join(f"{key} = {point[key]!r}" for key in grid)
        try:
            method.check_together(point, f"{where}.params" + (f" (grid point {shown})" if grid else ""))
        except ValueError as exc:
            raise SpecError(str(exc)) from None


def _parse_method(index: int, entry, base, plugins: list, fields=frozenset(), timeout=None) -> MethodSpec:
    where = f"methods[{index}]"
    entry = typed(where, entry, dict)
    check_keys(where, entry, {"method", "label", "params", "grid", "where", "timeout", "sources", "budgets"})
    timeout = _parse_timeout(f"{where}.timeout", entry["timeout"]) if "timeout" in entry else timeout
    if "method" not in entry:
        raise SpecError(f"{where}.method: missing (which registered method to run)")
    name = typed(f"{where}.method", entry["method"], str)
    if ":" in name:
        try:
            plugin = parse_plugin(name, base=base, function=True)
            load_plugins([plugin])
        except PluginError as exc:
            raise SpecError(f"{where}.method: {exc}") from None
        plugins.append(plugin)
    try:
        method = get_method(name)
    except UnknownMethodError as exc:
        raise SpecError(f"{where}.method: {exc}") from None
    label = typed(f"{where}.label", entry.get("label", method.label), str)
    params = typed(f"{where}.params", entry.get("params", {}), dict)
    grid = typed(f"{where}.grid", entry.get("grid", {}), dict)
    for key, values in grid.items():
        if not isinstance(values, list) or not values:
            raise SpecError(f"{where}.grid.{key}: expected a non-empty list of values, got {values!r}")
        if key in params:
            raise SpecError(f"{where}.grid.{key}: also set in params; set it in one place")
    try:
        method.check_params(params, f"{where}.params")
        for key, values in grid.items():
            for value in values:
                method.check_params({key: value}, f"{where}.grid")
    except ValueError as exc:
        raise SpecError(str(exc)) from None
    _check_together(where, method, params, grid)
    filters = typed(f"{where}.where", entry.get("where", {}), dict)
    for key, values in filters.items():
        if key not in fields:
            raise SpecError(f"{where}.where.{key}: unknown instance field (the instances have: "
                            f"{', '.join(sorted(fields))})")
        if not isinstance(values, list) or not values:
            raise SpecError(f"{where}.where.{key}: expected a non-empty list of values, got {values!r}")
    sources, budgets = _parse_sources(where, entry, method)
    return MethodSpec(name, label, dict(params), dict(grid), dict(filters), timeout, sources, budgets)


def _check_sources(methods: tuple) -> None:
    """Every ``sources`` item names an ordinary entry (its method or its label)."""
    known = {name for m in methods if not m.sources for name in (m.method, m.label)}
    for index, m in enumerate(methods):
        for source in m.sources:
            if source not in known:
                raise SpecError(f"methods[{index}].sources: {source!r} names no entry of this spec (entries: "
                                f"{', '.join(sorted(known))})")


def _parse_sources(where: str, entry: dict, method) -> tuple[tuple, tuple]:
    """An entry's ``sources`` (non-empty strings) and ``budgets`` (non-negative integers), checked."""
    if "budgets" in entry and "sources" not in entry:
        raise SpecError(f"{where}.budgets: applies only with sources (the entries whose graphs are refit)")
    if "sources" not in entry:
        return (), ()
    if "graph" not in method.hyperparameters:
        raise SpecError(f"{where}.sources: method {method.name!r} takes no graph to refit (use method \"refit\")")
    if "graph" in entry.get("params", {}) or "graph" in entry.get("grid", {}):
        raise SpecError(f"{where}.params.graph: set by the harness from each source design's graph; "
                        "give either sources or a graph")
    sources = typed(f"{where}.sources", entry["sources"], list)
    if not sources or not all(isinstance(s, str) and s for s in sources):
        raise SpecError(f"{where}.sources: expected a non-empty list of method names or labels, got {sources!r}")
    budgets = typed(f"{where}.budgets", entry.get("budgets", []), list)
    if not all(b == "any" or (isinstance(b, int) and not isinstance(b, bool) and b >= 0) for b in budgets):
        raise SpecError(f"{where}.budgets: expected non-negative integers (links) or \"any\", got {budgets!r}")
    budgets = {None if b == "any" else b for b in budgets}
    return tuple(sources), tuple(sorted(budgets, key=lambda b: (b is None, b or 0)))
