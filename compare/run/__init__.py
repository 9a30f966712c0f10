"""The run side of the harness: from an experiment spec to runs in a result store.

:mod:`~compare.run.spec` (specs and presets, with :mod:`~compare.run.parsing`'s helpers),
:mod:`~compare.run.families` (the instance families), :mod:`~compare.run.registry` and
:mod:`~compare.run.plugins` (the methods), :mod:`~compare.run.runner`,
:mod:`~compare.run.pool` and :mod:`~compare.run.execution` (running them),
:mod:`~compare.run.store` and :mod:`~compare.run.fingerprint` (keeping them), and what the
report side reads back: :mod:`~compare.run.records`, :mod:`~compare.run.meta` and
:mod:`~compare.run.drawing`; :mod:`~compare.run.export` writes the records as one table.

Nothing here imports :mod:`compare.report` (``tests/test_imports.py`` checks it).
"""
