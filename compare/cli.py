"""The ``compare`` command: run experiments, write reports, list methods and presets."""

from __future__ import annotations

import os
import sys
from pathlib import Path

import click

from .spec import SpecError, load_spec, preset_names

__all__ = ["main"]


class UserError(click.ClickException):
    """Bad input: a one-line message and exit code 2, no traceback."""

    exit_code = 2


def _store_path(out: Path, store: str | None) -> Path:
    return Path(store) if store else out / "results.sqlite"


def _open_store(path: Path):
    from .store import Store, StoreError

    try:
        return Store(path)
    except StoreError as exc:
        raise UserError(str(exc)) from None


def _write_report(store, out: Path) -> dict:
    from .report import write_report

    meta = store.meta()
    specs = {k.split(":", 1)[1]: v for k, v in meta.items() if k.startswith("spec:")}
    commands = [v for k, v in sorted(meta.items()) if k.startswith("command:")]
    commands.append(f"compare report --out {out}")
    title = "Comparison report: " + ", ".join(sorted(specs)) if specs else "Comparison report"
    return write_report(store.records(), out, specs=specs, title=title, commands=commands,
                        load_controller=store.controller, meta=meta, members=store.members(),
                        superseded=store.superseded())


_PLUGIN_HELP = ("Import a module (by name) or a .py file that registers methods with "
                "@codesign.methods.method; repeatable. Specs may also list `plugins = [...]` "
                "and name a plain function as method = \"module:function\".")


@click.group(context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(package_name="grnn-codesign")
def main():
    """Compare distributed controller designs on the same cost-versus-links axes."""


@main.command()
@click.argument("experiment", default="quick", metavar="[PRESET | FILE]")
@click.option("--out", type=click.Path(file_okay=False, path_type=Path), default=None,
              help="Report folder (default: reports/<experiment name>). The store lives there too.")
@click.option("--store", "store_path", type=click.Path(dir_okay=False), default=None,
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
    from .runner import ExecutorError, StoreBusy, run_experiment

    try:
        spec = load_spec(experiment, plugins=plugins)
    except SpecError as exc:
        raise UserError(str(exc)) from None
    if workers is not None and workers < 1:
        raise UserError(f"--workers must be >= 1, got {workers}")
    workers = workers or os.cpu_count() or 1
    out = out or Path("reports") / spec.name
    store = _open_store(_store_path(out, store_path))
    with store:
        try:
            summary = run_experiment(spec, store, workers=workers, progress=progress,
                                     executor=None if executor == "process" else executor, wait_for_others=wait)
        except (ExecutorError, StoreBusy) as exc:
            raise UserError(str(exc)) from None
        except KeyboardInterrupt:
            click.echo(f"\ninterrupted: {len(store)} runs are stored in {store.path}; "
                       "run the same command again to resume.", err=True)
            sys.exit(130)
        click.echo(str(summary))
        command = f"compare run {experiment}" + (f" --out {out}" if out != Path("reports") / spec.name else "")
        store.set_meta(f"command:{spec.name}", command)
        files = _write_report(store, out)
    click.echo(f"report: {files['md']}")


@main.command()
@click.option("--out", type=click.Path(file_okay=False, path_type=Path), default=Path("reports/quick"),
              show_default=True, help="Report folder holding the store.")
@click.option("--store", "store_path", type=click.Path(dir_okay=False), default=None,
              help="Result store file (default: <out>/results.sqlite).")
def report(out, store_path):
    """Regenerate the report from the result store alone."""
    path = _store_path(out, store_path)
    if not path.is_file():
        raise UserError(f"no result store at {path}; run `compare run` first or pass --store")
    with _open_store(path) as store:
        if len(store) == 0:
            raise UserError(f"the store {path} holds no runs")
        files = _write_report(store, out)
    click.echo(f"report: {files['md']}")


@main.command()
@click.option("--plugin", "plugins", multiple=True, metavar="MODULE_OR_FILE", help=_PLUGIN_HELP)
def methods(plugins):
    """List the registered design methods, their hyperparameters and defaults."""
    from .plugins import PluginError, load_plugins, parse_plugin
    from .registry import methods as registered_methods

    try:
        load_plugins([parse_plugin(ref) for ref in plugins])
    except PluginError as exc:
        raise UserError(str(exc)) from None
    for name, method in sorted(registered_methods().items()):
        click.echo(f"{name}  ({method.label}): {method.summary}")
        for h in method.hyperparameters.values():
            doc = h.doc if len(h.doc) <= 90 else h.doc[:89].rstrip() + "…"
            meaning = f"  {doc}" if doc else ""
            click.echo(f"    {h.name}: {h.type_name} = {h.default!r}{meaning}")


@main.command()
@click.argument("name", required=False)
def presets(name):
    """List the shipped presets, or print one preset's spec."""
    if name:
        try:
            click.echo(load_spec(name).source.rstrip())
        except SpecError as exc:
            raise UserError(str(exc)) from None
        return
    for preset in preset_names():
        spec = load_spec(preset)
        click.echo(f"{preset:<16} {len(spec.runs())} runs  {spec.description}")


if __name__ == "__main__":  # pragma: no cover
    main()
