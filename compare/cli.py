"""The ``compare`` command: run experiments, write reports, export results, list methods and presets.

Importing this module imports click and nothing heavy: each command imports what it
needs (the method registry pulls in torch and cvxpy, reports matplotlib), so
``compare --help`` and bad-input errors answer at once.
"""

from __future__ import annotations

import os
import sys
import warnings
from contextlib import contextmanager
from importlib import resources
from pathlib import Path

import click

__all__ = ["main"]

#: Approximate wall time of ``compare run PRESET`` on 2 cores (2 workers), report included.
#: A preset missing here is listed as "not measured".
PRESET_TIMES = {
    "quick": "~1 min (51-64 s measured, 56-57 s on 2026-11-27; 67-78 s the first time, compiling the fused kernels)",
    "baselines-small": "~20 s (16 s measured)",
    "sls-small": "~15 s (15 s measured)",
    "table1-small": "~40 s (38 s measured)",
    "table1": "~5 min (275-320 s measured, 275 s and 294 s on 2026-11-27)",
    "tradeoff": "~21 min (1261 s and 1279 s measured on 2026-11-27; 1363-1466 s before)",
    "systems": "~3 min (172-215 s measured, 173 s on 2026-11-27)",
    "scale": "~17-19 min (1023-1154 s measured, 1028 s and 1066 s on 2026-11-27)",
    "small": "~7-11 min (420-670 s measured, 536 s and 555 s on 2026-11-27)",
    "benchmark-systems": "~6-7 min (349-416 s measured, 377-378 s on 2026-11-27)",
    "scale-large": "~60 min (3486 s on 2026-11-28, with short tests beside it part of the time; 3806 s before)",
    "power": "~4 min (234 s measured on 2026-11-28)",
    "learned-class": "~35 min (2234 runs; measured once, on 2026-11-28)",
    "topology": "~45 min from an empty store (3587 runs, 2753 s of runs on 2026-12-07; about 37 min with "
                "learned-class's shared runs already stored)",
}


#: Where `compare run` writes when no --out is given: untracked, so running leaves a checkout clean.
#: The reports shipped with the repository are regenerated explicitly with --out reports/<name>.
RESULTS = Path("results")


class UserError(click.ClickException):
    """Bad input: a one-line message and exit code 2, no traceback."""

    exit_code = 2


def _store_path(out: Path, store: str | None) -> Path:
    return Path(store) if store else out / "results.sqlite"


def _check_folder(path: Path, option: str = "--out") -> None:
    """A folder argument must not name an existing file (or sit under one)."""
    for part in (path, *path.parents):
        if part.exists():
            if not part.is_dir():
                what = "is a file" if part == path else f"is inside {part}, which is a file"
                raise UserError(f"{option} {path} {what}; give a folder")
            return


def _check_file(path: Path, option: str = "--store") -> None:
    if path.is_dir():
        raise UserError(f"{option} {path} is a folder; give the result store file")


def _check_writable(path: Path, option: str = "--out") -> None:
    """The folder (or the nearest folder above it that exists) must be writable, checked before any work."""
    for part in (path, *path.parents):
        if part.exists():
            if not os.access(part, os.W_OK | os.X_OK):
                where = "" if part == path else f" (its parent {part} is not writable)"
                raise UserError(f"{option} {path} is not writable{where}; give a folder you can write to")
            return


def _open_store(path: Path, *, create: bool = True, read_only: bool = False):
    from .run.store import Store, StoreError

    try:
        return Store(path, create=create, read_only=read_only)
    except StoreError as exc:
        raise UserError(str(exc)) from None
    except OSError as exc:
        raise UserError(f"cannot open the result store {path}: {exc.strerror or exc}") from None


@contextmanager
def _reading_store(path: Path):
    """An existing store opened read-only for ``compare report`` or ``export`` (its bytes stay as they were);
    a store fault while reading exits 2."""
    from .run.store import StoreError

    with _open_store(path, create=False, read_only=True) as store:
        try:
            yield store
        except StoreError as exc:
            raise UserError(str(exc)) from None


def _interrupt(signum, frame):
    raise KeyboardInterrupt


@contextmanager
def _interrupt_on_sigterm():
    """SIGTERM ends a run as Ctrl-C does: workers stopped, claims released, a line saying what is stored."""
    import signal

    try:
        previous = signal.signal(signal.SIGTERM, _interrupt)
    except ValueError:  # not the main thread: leave the default
        yield
        return
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, previous)


@contextmanager
def _store_for_run(path: Path):
    """The store a run writes; one this command created is removed again if the command fails before any run.

    So are the folders it was created in, where this command made them and they hold nothing
    else: a failed or interrupted first run leaves no empty output folder behind.
    """
    from .run.store import StoreError

    created = not path.exists()
    made = [folder for folder in (path.parent, *path.parent.parents) if not folder.exists()]  # innermost first
    store = _open_store(path)
    try:
        yield store
    except BaseException:
        try:
            empty = len(store) == 0
        except StoreError:  # the store itself failed: keep the file as it is
            empty = False
        store.close()
        if created and empty:
            path.unlink(missing_ok=True)
            for folder in made:
                try:
                    folder.rmdir()
                except OSError:  # something else was written there: keep it
                    break
        raise
    store.close()


def _preset_names() -> list[str]:
    """The shipped presets, read from the package folder (no spec parsing, no method imports)."""
    folder = resources.files("compare.run") / "presets"
    return sorted(p.name[:-5] for p in folder.iterdir() if p.name.endswith(".toml"))


class _RunCommand(click.Command):
    """``compare run``, whose help ends with the presets and their run times (read when help is shown)."""

    def format_epilog(self, ctx, formatter):
        rows = [(name, PRESET_TIMES.get(name, "not measured")) for name in _preset_names()]
        with formatter.section("Presets (approximate run time on 2 cores; `compare presets` describes them)"):
            formatter.write_dl(rows)


def _report(records, out: Path, *, meta: dict, members: dict, superseded: int, load_controller,
            software: dict | None = None) -> dict:
    """Write the report of ``records`` into ``out``: titles, specs and commands come from ``meta``."""
    from .report.write import write_report
    from .run.meta import MetaError, StoreMeta

    try:
        store_meta = StoreMeta.parse(meta)
    except MetaError as exc:
        raise UserError(f"cannot write the report: {exc}") from None
    specs = dict(store_meta.specs)
    commands = [store_meta.commands[name] for name in sorted(store_meta.commands)]
    commands.append(f"compare report --out {out}")
    title = "Comparison report: " + ", ".join(sorted(specs)) if specs else "Comparison report"
    # software is None from a store: the report prints the installed versions.
    try:
        return write_report(records, out, specs=specs, title=title, commands=commands,
                            load_controller=load_controller, meta=store_meta, members=members,
                            superseded=superseded, software=software)
    except OSError as exc:
        raise UserError(f"cannot write the report to {out}: {exc.strerror or exc} (stored runs are kept; "
                        "`compare report` writes it again)") from None


def _write_report(store, out: Path) -> dict:
    """The report of everything current in ``store``."""
    return _report(store.records(), out, meta=store.meta(), members=store.members(), superseded=store.superseded(),
                   load_controller=store.controller)


def _write_report_from_folder(data, out: Path) -> dict:
    """The report of a :class:`compare.report.folder.FolderData`, with the software versions it recorded."""
    return _report(data.records, out, meta=data.meta, members=data.members, superseded=data.superseded,
                   load_controller=data.load_controller, software=data.software)


def _rebuild_from_folder(out: Path) -> dict:
    """Rebuild the report of a folder from its runs.csv, curves.csv and report.json; bad files exit 2."""
    from .report.folder import FolderError, read_folder

    try:
        data = read_folder(out)
    except FolderError as exc:
        raise UserError(str(exc)) from None
    return _write_report_from_folder(data, out)


_PLUGIN_HELP = ("Import a module (by name) or a .py file that registers methods with "
                "@codesign.methods.method; repeatable. Specs may also list `plugins = [...]` "
                "and name a plain function as method = \"module:function\".")


@contextmanager
def _held_warnings():
    """Hold this process's warnings (and those workers send back) until the command ends.

    A command refused for bad input then prints its one ``Error:`` line alone: a library's
    warning on the way there (scipy's, say, while an instance file is checked) is dropped.
    Otherwise each distinct warning is shown at the end, once.
    """
    try:
        with warnings.catch_warnings(record=True) as caught:
            yield
    except click.ClickException:
        raise
    except BaseException:
        _show_warnings(caught)
        raise
    _show_warnings(caught)


def _show_warnings(caught) -> None:
    """Each distinct warning once, on stderr, as Python prints them."""
    shown = set()
    for w in caught:
        key = (w.category, str(w.message), w.filename, w.lineno)
        if key not in shown:
            shown.add(key)
            click.echo(warnings.formatwarning(w.message, w.category, w.filename, w.lineno), err=True, nl=False)


class _Group(click.Group):
    """The ``compare`` group: every command runs with its warnings held (:func:`_held_warnings`)."""

    def invoke(self, ctx):
        with _held_warnings():
            return super().invoke(ctx)


@click.group(cls=_Group, context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(package_name="grnn-codesign")
def main():
    """Compare distributed controller designs on the same cost-versus-links axes."""


@main.command(cls=_RunCommand)
@click.argument("experiment", default="quick", metavar="[PRESET | FILE]")
@click.option("--out", type=click.Path(path_type=Path), default=None,
              help="Report folder (default: results/<experiment name>, which git ignores). "
                   "The store lives there too.")
@click.option("--store", "store_path", type=click.Path(path_type=Path), default=None, metavar="FILE",
              help="Result store file (default: <out>/results.sqlite).")
@click.option("--workers", type=int, default=None,
              help="Worker processes (default: number of CPU cores; 1 runs in this process).")
@click.option("--executor", default="process", show_default=True,
              help="Where runs execute: 'process' (local pool), 'dask-local' (a local dask cluster) "
                   "or 'dask://HOST:PORT' (a running dask scheduler).")
@click.option("--progress/--no-progress", default=True, help="Show a progress bar.")
@click.option("--plugin", "plugins", multiple=True, metavar="MODULE_OR_FILE", help=_PLUGIN_HELP)
@click.option("--wait/--no-wait", default=True,
              help="When another `compare run` is computing runs of this experiment on the same store: "
                   "wait for them (default), or stop with exit code 2.")
def run(experiment, out, store_path, workers, executor, progress, plugins, wait):
    """Run an experiment (a preset name or a TOML spec file), then write its report.

    Runs already in the store with the same code fingerprint are skipped, so an
    interrupted run resumes where it stopped and an edited method reruns only its
    own runs. Your own methods come in as plug-ins (--plugin, or `plugins` and
    method = "module:function" in the spec); `compare methods --plugin ...` lists them.
    """
    if workers is not None and workers < 1:
        raise UserError(f"--workers must be >= 1, got {workers}")
    if executor not in ("process", "dask-local") and not executor.startswith(("dask://", "tcp://")):
        # Checked here too (open_executor says the same) so that it answers before the methods are imported.
        raise UserError(f"unknown executor {executor!r}: use 'process', 'dask-local' or 'dask://HOST:PORT'")
    if out is not None:
        _check_folder(out)
    if store_path is not None:
        _check_file(store_path)
    from .run.meta import MetaKind, meta_key
    from .run.runner import ExecutorError, StoreBusy, open_executor, run_experiment
    from .run.spec import SpecError, load_spec
    from .run.store import StoreError

    try:
        spec = load_spec(experiment, plugins=plugins)
    except SpecError as exc:
        raise UserError(str(exc)) from None
    workers = workers or os.cpu_count() or 1
    out = out or RESULTS / spec.name
    _check_folder(out)
    _check_writable(out)
    path = _store_path(out, store_path)
    _check_writable(path.parent, "--store")
    new_store = not path.exists()
    try:
        # The executor first: an address that does not work is refused before a store is created.
        with _interrupt_on_sigterm(), open_executor(executor, workers) as pool, _store_for_run(path) as store:
            try:
                summary = run_experiment(spec, store, workers=workers, progress=progress, executor=pool,
                                         wait_for_others=wait)
            except KeyboardInterrupt:
                stored = len(store)
                if stored == 0 and new_store:  # _store_for_run removes the store it created: do not name it
                    click.echo("\ninterrupted before any run was stored; nothing was kept. Run the same command "
                               "again to start.", err=True)
                else:
                    click.echo(f"\ninterrupted: {stored} runs are stored in {store.path}; "
                               "run the same command again to resume.", err=True)
                sys.exit(130)
            click.echo(str(summary))
            command = f"compare run {experiment}" + (f" --out {out}" if out != RESULTS / spec.name else "")
            store.set_meta(meta_key(MetaKind.COMMAND, spec.name), command)
            files = _write_report(store, out)
    except (ExecutorError, StoreBusy, StoreError) as exc:
        raise UserError(str(exc)) from None
    click.echo(f"report: {files['md']}")


@main.command()
@click.option("--out", type=click.Path(path_type=Path), default=RESULTS / "quick",
              show_default=True, help="Report folder holding the store.")
@click.option("--store", "store_path", type=click.Path(path_type=Path), default=None, metavar="FILE",
              help="Result store file (default: <out>/results.sqlite).")
def report(out, store_path):
    """Regenerate the report from the result store alone.

    Without a store (none in the folder and no --store), a folder holding runs.csv and
    report.json, as every report since they were added does, is rebuilt from those.
    """
    _check_folder(out)
    if store_path is not None:
        _check_file(store_path)
    path = _store_path(out, store_path)
    folder_files = any((out / name).is_file() for name in ("runs.csv", "report.json"))
    if not path.is_file() and store_path is None and folder_files:
        files = _rebuild_from_folder(out)
        click.echo("rebuilt from the folder's runs.csv and report.json (no result store)")
        click.echo(f"report: {files['md']}")
        return
    if not path.is_file():
        rebuild = "" if store_path is not None else f" and no runs.csv or report.json in {out} to rebuild from"
        raise UserError(f"no result store at {path}{rebuild}; run `compare run` first or pass --store")
    _check_writable(out)
    with _reading_store(path) as store:
        if len(store) == 0:
            raise UserError(f"the store {path} holds no runs")
        files = _write_report(store, out)
    click.echo(f"report: {files['md']}")


@main.command("export")
@click.option("--out", type=click.Path(path_type=Path), required=True,
              help="Folder to write designs.csv (or designs.parquet) into; created if missing.")
@click.option("--store", "store_path", type=click.Path(path_type=Path), default=None, metavar="FILE",
              help="Result store file to read.")
@click.option("--from", "report_dir", type=click.Path(path_type=Path), default=None, metavar="REPORT_DIR",
              help="Report folder whose results.sqlite to read (default: the --out folder's).")
@click.option("--format", "fmt", default="csv", show_default=True, metavar="csv|parquet",
              help="File format; parquet needs pyarrow.")
def export(out, store_path, report_dir, fmt):
    """Write every current design as one table, ready for pandas.

    One row per design: the method, label and instance fields (family, n, a_norm,
    seed, ...), cost, links and status, one column per hyperparameter (gamma,
    beta, ...; empty where a method has none) and the scalar extras. The same table
    is `Store(path).to_pandas()` in Python. Needs the optional extra:
    pip install -e ".[analysis]".
    """
    from .run.export import FORMATS, MissingExtra, require_pandas

    if fmt not in FORMATS:
        raise UserError(f"--format: unknown format {fmt!r} (known: {', '.join(FORMATS)})")
    if store_path is not None and report_dir is not None:
        raise UserError("give --store FILE or --from REPORT_DIR, not both")
    _check_folder(out)
    if report_dir is not None:
        _check_folder(report_dir, "--from")
    if store_path is not None:
        _check_file(store_path)
        path = store_path
    else:
        path = (report_dir if report_dir is not None else out) / "results.sqlite"
    if not path.is_file():
        if store_path is not None:
            raise UserError(f"no result store at {path} (--store)")
        if report_dir is not None:
            raise UserError(f"no result store in {report_dir} (--from): {path} does not exist")
        raise UserError(f"no result store at {path}; name one with --store FILE or --from REPORT_DIR")
    try:
        require_pandas(fmt)
    except MissingExtra as exc:
        raise UserError(str(exc)) from None
    from .run.export import write_designs

    with _reading_store(path) as store:
        if len(store) == 0:
            raise UserError(f"the store {path} holds no runs")
        frame = store.to_pandas()
    try:
        written = write_designs(frame, out, fmt)
    except OSError as exc:
        raise UserError(f"cannot write to {out}: {exc.strerror or exc}") from None
    click.echo(f"{len(frame)} designs, {frame.shape[1]} columns: {written}")


def _load_listed_plugins(plugins) -> None:
    """Load the --plugin modules or files of a listing command (a bad one is a one-line error)."""
    from .run.plugins import PluginError, load_plugins, parse_plugin

    try:
        load_plugins([parse_plugin(ref) for ref in plugins])
    except PluginError as exc:
        raise UserError(str(exc)) from None


@main.command()
@click.option("--plugin", "plugins", multiple=True, metavar="MODULE_OR_FILE", help=_PLUGIN_HELP)
def methods(plugins):
    """List the registered design methods, their hyperparameters and defaults."""
    from .run.registry import methods as registered_methods

    _load_listed_plugins(plugins)
    for name, method in sorted(registered_methods().items()):
        click.echo(f"{name}  ({method.label}): {method.summary}")
        if method.max_states is not None:
            click.echo(f"    runs on at most {method.max_states} states: {method.max_states_reason}")
        for h in method.hyperparameters.values():
            doc = h.doc if len(h.doc) <= 90 else h.doc[:89].rstrip() + "…"
            meaning = f"  {doc}" if doc else ""
            click.echo(f"    {h.name}: {h.type_name} = {h.default!r}{meaning}")


@main.command()
@click.argument("name", required=False)
def presets(name):
    """List the shipped presets, or print one preset's spec."""
    from .run.spec import SpecError, load_spec, preset_names

    if name:
        try:
            click.echo(load_spec(name).source.rstrip())
        except SpecError as exc:
            raise UserError(str(exc)) from None
        return
    for preset in preset_names():
        spec = load_spec(preset)
        click.echo(f"{preset:<16} {len(spec.runs())} runs  {spec.description}")


@main.command()
@click.option("--plugin", "plugins", multiple=True, metavar="MODULE_OR_FILE", help=_PLUGIN_HELP)
def families(plugins):
    """List the instance families an [instances] table can name, and the fields 'where' filters on."""
    from .run.families import family_names, get_family

    _load_listed_plugins(plugins)
    for name in family_names():
        family = get_family(name)
        click.echo(f"{name}: {family.summary}")
        if family.fields:
            click.echo(f"    fields: {', '.join(sorted(family.fields))}")


if __name__ == "__main__":  # pragma: no cover
    main()
