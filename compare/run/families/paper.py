"""The paper's random family (Yang & Matni §IV; docs/problem.md): :func:`codesign.paper_instance`.

Every (n, a_norm, seed) combination of the spec's lists is one instance; the
other keys are shared. Keys and defaults: ``n = [20]``, ``a_norms = [0.995]``,
``seeds = 1`` (a count, or a list of seeds), ``degree = 6``, ``b_norm = 1.0``,
``hops = 3``, ``horizon = 50``, ``connect = "redraw"`` (the paper's: positions drawn
again until the graph is connected; ``"bridge"`` links across the gaps of the first
draw instead, the only way past a few hundred nodes, and is then part of the spec).
"""

from __future__ import annotations

from codesign.instances import CONNECT_RULES

from ..parsing import SpecError, check_keys, list_of, typed
from . import Family, register_family

KEYS = {"family", "n", "a_norms", "seeds", "degree", "b_norm", "hops", "horizon", "connect"}


def _seeds(value) -> tuple:
    if isinstance(value, int) and not isinstance(value, bool):
        if value < 1:
            raise SpecError(f"instances.seeds: a count must be >= 1, got {value}")
        return tuple(range(value))
    seeds = list_of("instances.seeds", typed("instances.seeds", value, list), int, positive=False)
    if any(s < 0 for s in seeds):
        raise SpecError(f"instances.seeds: seeds must be non-negative, got {list(seeds)}")
    if len(set(seeds)) != len(seeds):
        raise SpecError(f"instances.seeds: duplicate seeds in {list(seeds)}")
    return seeds


def parse(table: dict, base=None) -> tuple:
    check_keys("instances", table, KEYS)
    seeds = _seeds(table.get("seeds", 1))
    sizes = list_of("instances.n", table.get("n", [20]), int)
    a_norms = list_of("instances.a_norms", table.get("a_norms", [0.995]), float)
    shared = {
        "degree": typed("instances.degree", table.get("degree", 6), int),
        "b_norm": typed("instances.b_norm", table.get("b_norm", 1.0), float),
        "hops": typed("instances.hops", table.get("hops", 3), int),
        "horizon": typed("instances.horizon", table.get("horizon", 50), int),
    }
    if any(n < 2 for n in sizes):
        raise SpecError(f"instances.n: sizes must be >= 2, got {list(sizes)}")
    if any(shared["degree"] > n for n in sizes):
        raise SpecError(f"instances.degree: {shared['degree']} exceeds n = {min(sizes)}")
    for key, low in (("degree", 2), ("horizon", 1)):  # paper_instance's own limits
        if shared[key] < low:
            raise SpecError(f"instances.{key}: must be >= {low}, got {shared[key]}")
    if shared["hops"] < 0:
        raise SpecError(f"instances.hops: must be >= 0, got {shared['hops']}")
    if shared["b_norm"] <= 0:
        raise SpecError(f"instances.b_norm: must be positive, got {shared['b_norm']}")
    connect = typed("instances.connect", table.get("connect", "redraw"), str)
    if connect not in CONNECT_RULES:
        raise SpecError(f"instances.connect: must be one of {', '.join(CONNECT_RULES)}, got {connect!r}")
    extra = {} if connect == "redraw" else {"connect": connect}
    return tuple({"family": "paper", "seed": seed, "n": n, "degree": shared["degree"], "a_norm": a_norm,
                  "b_norm": shared["b_norm"], "hops": shared["hops"], "horizon": shared["horizon"], **extra}
                 for n in sizes for a_norm in a_norms for seed in seeds)


def build(spec: dict):
    from codesign import paper_instance

    kwargs = {k: v for k, v in spec.items() if k != "family"}
    return paper_instance(**kwargs)


PAPER = register_family(Family(
    name="paper",
    summary="the paper's random family: N nodes on a k-nearest-neighbour graph, A scaled to ||A||_2 = a_norm",
    parse=parse,
    build=build,
    fields=frozenset({"seed", "n", "degree", "a_norm", "b_norm", "hops", "horizon", "connect"}),
))
