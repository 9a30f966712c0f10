"""The tiny experiment that the CLI, store, spec, plug-in, executor and report tests share.

Four instances of the paper's family at N = 8 (seeds 0 and 1 at ‖A‖₂ = 0.995 and 1.05,
degree 4, horizon 10), on which every cheap method runs in milliseconds.
:func:`tiny_spec` writes its TOML text; each test file's own variant names its
differences as keywords (another name, other methods, a third seed, ...).
"""

from __future__ import annotations

#: The spectral norms of A: one stable system, one unstable.
A_NORMS = (0.995, 1.05)
#: The methods of the plain spec: cheap, and each with its own link count.
METHODS = ("lqr", "autonomous", "decentralized")


def method_entries(*methods: str) -> str:
    """One ``[[methods]]`` entry per method name, each with its ``method`` key alone."""
    return "".join(f'[[methods]]\nmethod = "{method}"\n' for method in methods)


def tiny_spec(name: str = "tiny", *, methods=METHODS, head: str = "", family: str | None = None,
              a_norms=A_NORMS, seeds: int = 2, tail: str = "") -> str:
    """The tiny experiment's spec as TOML text.

    Parameters
    ----------
    name : str
        The experiment's name.
    methods : sequence of str
        The methods, one ``[[methods]]`` entry each, in order.
    head : str
        Lines between the name and ``[instances]`` (a description, a ``[report]`` table).
    family : str, optional
        Written as ``family = "..."`` first in ``[instances]`` (by default no line: the paper's family).
    a_norms : sequence of float
        The instances' ``a_norms``.
    seeds : int
        The instances' seed count.
    tail : str
        Text after the last entry: more keys of the last ``[[methods]]`` entry (``params``, ``grid``).

    Returns
    -------
    str
    """
    family_line = f'family = "{family}"\n' if family else ""
    norms = ", ".join(str(a) for a in a_norms)
    return (f'\nname = "{name}"\n{head}[instances]\n{family_line}n = [8]\na_norms = [{norms}]\nseeds = {seeds}\n'
            f"degree = 4\nhorizon = 10\n{method_entries(*methods)}{tail}")
