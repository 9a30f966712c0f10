"""Instance families: the paper family keeps its run keys, and systems from .npz files run end to end."""

from __future__ import annotations

import numpy as np
import pytest
from click.testing import CliRunner

from codesign import paper_instance
from compare import SpecError, parse_spec
from compare.cli import main
from compare.run.families import Family, family_names, get_family, register_family
from compare.run.store import Store

SPEC = """
name = "mine"
[instances]
family = "matrices"
files = ["systems/*.npz"]
[[methods]]
method = "lqr"
[[methods]]
method = "decentralized"
[[methods]]
method = "truncated_lqr"
grid = { links = [[4], [12]] }
"""


def _system(seed: int) -> dict:
    inst = paper_instance(seed, n=6, degree=3, a_norm=1.05, horizon=10)
    return {"A": inst.A, "B": inst.B, "comm_adj": inst.comm_adj, "horizon": np.array(10)}


def _write_systems(folder):
    systems = folder / "systems"
    systems.mkdir()
    for seed in (0, 1):
        np.savez(systems / f"sys{seed}.npz", **_system(seed))
    (folder / "mine.toml").write_text(SPEC)
    return folder / "mine.toml"


def _run(spec, out):
    return CliRunner().invoke(main, ["run", str(spec), "--out", str(out), "--workers", "1", "--no-progress"])


def test_builtin_families_are_listed():
    assert {"paper", "matrices", "mass_spring", "random_network"} <= set(family_names())


def test_systems_from_files_run_end_to_end_and_edits_rerun_only_that_file(tmp_path):
    spec = _write_systems(tmp_path)
    out = tmp_path / "out"
    first = _run(spec, out)
    assert first.exit_code == 0, first.output
    assert "8 runs: 8 computed" in first.output
    with Store(out / "results.sqlite") as store:
        records = store.records()
    lqr = [r for r in records if r.method == "lqr"]
    assert sorted(r.instance.spec["name"] for r in lqr) == ["sys0", "sys1"]
    for r in lqr:
        assert abs(r.cost - 1.0) < 1e-9 and r.links == 30
    assert "matrices, N = 6" in (out / "report.md").read_text()

    # Editing one file recomputes its runs only.
    edited = _system(0)
    edited["A"] = edited["A"] * 1.01
    np.savez(tmp_path / "systems" / "sys0.npz", **edited)
    second = _run(spec, out)
    assert second.exit_code == 0, second.output
    assert "8 runs: 4 computed, 4 already stored" in second.output

    # Moving a file keeps its runs: the identity is the contents, not the path.
    (tmp_path / "systems" / "sys1.npz").rename(tmp_path / "systems" / "renamed.npz")
    third = _run(spec, out)
    assert third.exit_code == 0, third.output
    assert "8 runs: 0 computed, 8 already stored" in third.output


def _bad(tmp_path, arrays, name="bad.npz"):
    (tmp_path / "systems").mkdir(exist_ok=True)
    np.savez(tmp_path / "systems" / name, **arrays)
    (tmp_path / "mine.toml").write_text(SPEC)
    return _run(tmp_path / "mine.toml", tmp_path / "out")


@pytest.mark.parametrize("change, message", [
    (lambda s: s.pop("B"), "missing array(s) B"),
    (lambda s: s.update(A=np.full((6, 6), np.nan)), "non-finite"),
    (lambda s: s.update(B=np.zeros((6, 6))), "not stabilizable"),
    (lambda s: s.update(B=np.eye(5)), "B"),
    (lambda s: s.update(extra=np.eye(6)), "unknown array(s) extra"),
    (lambda s: s.update(state_nodes=np.array([0, 0, 1, 1, 2, 2])), "B has 6 columns but there are 3 nodes"),
    (lambda s: s.update(state_nodes=np.array([0, 0, 1, 1, 3, 3]), input_nodes=np.arange(6) // 2),
     "nodes [2] have none"),
    (lambda s: s.update(Q=np.zeros((6, 6))), "Q must not be zero"),
])
def test_bad_files_are_one_line_errors_naming_the_file(tmp_path, change, message):
    arrays = _system(0)
    change(arrays)
    result = _bad(tmp_path, arrays)
    assert result.exit_code == 2, result.output
    assert "bad.npz" in result.output and message in result.output
    assert "Traceback" not in result.output
    assert not (tmp_path / "out" / "results.sqlite").exists()


def test_a_file_that_is_not_npz_is_named(tmp_path):
    (tmp_path / "systems").mkdir()
    (tmp_path / "systems" / "junk.npz").write_text("not an archive")
    (tmp_path / "mine.toml").write_text(SPEC)
    result = _run(tmp_path / "mine.toml", tmp_path / "out")
    assert result.exit_code == 2 and "junk.npz: not a readable .npz file" in result.output


@pytest.mark.parametrize("instances, message", [
    ('family = "matrices"\nfiles = ["nothing*.npz"]', "instances.files[0]: no file matches"),
    ('family = "matrices"', "instances.files: required"),
    ('family = "matrices"\nfiles = ["x.npz"]\nseeds = 3', "instances.seeds: unknown key (allowed: family, files)"),
    ('family = "mass_sprung"', "instances.family: unknown family 'mass_sprung' (known: chain, mass_spring, matrices, paper, platoon, power_grid, random_network, swing_grid"),
    ('family = "paper"\nfiles = ["x.npz"]', "instances.files: unknown key"),
    ('family = "paper"\nconnect = "glue"', "instances.connect: must be one of redraw, bridge, got 'glue'"),
])
def test_instance_keys_are_validated_per_family(tmp_path, instances, message):
    with pytest.raises(SpecError) as info:
        parse_spec(f'name = "x"\n[instances]\n{instances}\n[[methods]]\nmethod = "lqr"\n', base=tmp_path)
    assert message in str(info.value)


def test_bridged_paper_instances_carry_connect_and_can_be_filtered():
    spec = parse_spec('name = "x"\n[instances]\nn = [8]\nseeds = 2\nconnect = "bridge"\n'
                      '[[methods]]\nmethod = "lqr"\nwhere = { connect = ["bridge"], seed = [1] }\n')
    assert [s["connect"] for s in spec.instances.expand()] == ["bridge", "bridge"]
    assert [r.instance["seed"] for r in spec.runs()] == [1]
    plain = parse_spec('name = "x"\n[instances]\nn = [8]\n[[methods]]\nmethod = "lqr"\n')
    assert "connect" not in plain.instances.expand()[0]


def test_where_filters_name_the_familys_fields(tmp_path):
    _write_systems(tmp_path)
    text = SPEC.replace('method = "decentralized"', 'method = "decentralized"\nwhere = { a_norm = [1.05] }')
    with pytest.raises(SpecError, match=r"where.a_norm: unknown instance field \(the instances have: family, n, name\)"):
        parse_spec(text, base=tmp_path)
    ok = parse_spec(SPEC.replace('method = "decentralized"', 'method = "decentralized"\nwhere = { name = ["sys1"] }'),
                    base=tmp_path)
    assert sum(r.method == "decentralized" for r in ok.runs()) == 1


def test_a_family_of_ones_own_can_be_registered(tmp_path):
    def parse(table, base=None):
        return tuple({"family": "tiny_chain", "n": n} for n in table.get("n", [4]))

    def build(spec):
        from codesign import Instance

        n = spec["n"]
        A = 1.02 * np.eye(n) + 0.1 * np.eye(n, k=1)
        return Instance.from_matrices(A, np.eye(n), horizon=8, name=f"chain{n}")

    register_family(Family("tiny_chain", "a test chain", parse, build, frozenset({"n"})))
    spec = parse_spec('name = "c"\n[instances]\nfamily = "tiny_chain"\nn = [3, 5]\n[[methods]]\nmethod = "lqr"\n')
    assert [r.instance["n"] for r in spec.runs()] == [3, 5]
    assert get_family("tiny_chain").build({"family": "tiny_chain", "n": 3}).n == 3


# -- nodes with several states: the mass-spring chain ------------------------------------------
from codesign import Instance, compare_exact_and_simulated, count_links, get_method  # noqa: E402
from compare.run.families.mass_spring import mass_spring_instance  # noqa: E402


@pytest.fixture(scope="module")
def chain():
    return mass_spring_instance(8)


def test_mass_spring_nodes_hold_a_position_and_a_velocity(chain):
    assert (chain.n, chain.m, chain.nodes) == (16, 8, 8) and not chain.scalar_nodes
    np.testing.assert_array_equal(chain.state_nodes, np.r_[np.arange(8), np.arange(8)])
    chain_graph = np.eye(8) + np.eye(8, k=1) + np.eye(8, k=-1)
    np.testing.assert_array_equal(chain.comm_adj, chain_graph)
    assert chain.spec == {"family": "mass_spring", "n": 8, "seed": 0, "dt": 0.2, "horizon": 50, "r": 10.0}
    np.testing.assert_array_equal(chain.R, 10.0 * np.eye(8))  # lqrsp's example: Q = I, R = 10 I
    assert mass_spring_instance(8, seed=1).A.tolist() != chain.A.tolist()


def test_lqr_and_the_block_diagonal_gain_count_links_between_nodes(chain):
    lqr = get_method("lqr")(chain)[0]
    assert abs(lqr.cost - 1.0) < 1e-9 and (lqr.links, lqr.self_loops) == (56, 8)
    local = get_method("decentralized")(chain)[0]
    assert local.status == "optimal" and (local.links, local.self_loops) == (0, 8)
    K = local.controller.K
    assert K.shape == (8, 16) and np.all(K[~chain.block_mask()] == 0) and np.any(K[chain.block_mask()] != 0)
    assert local.cost < get_method("autonomous")(chain)[0].cost


def test_exact_and_simulated_costs_agree_for_a_block_sparse_gain(chain):
    rng = np.random.default_rng(3)
    node_links = np.zeros((8, 8), bool)
    node_links[[0, 3, 5], [1, 2, 6]] = True
    allowed = chain.block_mask() | node_links[chain.input_nodes][:, chain.state_nodes]
    K = np.where(allowed, np.asarray(get_method("decentralized")(chain)[0].controller.K) + 0.05 *
                 rng.standard_normal((8, 16)), 0.0)
    from codesign import StaticGain, score

    design = score(chain, StaticGain(K))
    assert design.cost_kind == "exact" and (design.links, design.self_loops) == (3, 8)
    check = compare_exact_and_simulated(chain, StaticGain(K))
    assert abs(check["z"]) < 3
    np.testing.assert_allclose(check["control_variate"], check["exact"], rtol=1e-9)
    assert count_links(chain.node_support(K)) == (3, 8)


def test_sls_on_node_blocks(chain):
    """Unconstrained SLS (complete graph, no delay, fast relay) is LQR; delays cost; the given chain is not QI."""
    sls = get_method("sls")
    (free,) = sls(chain, graph="complete", act_delay=0, speed=10.0, horizon=20)
    assert free.status == "optimal" and abs(free.cost - 1.0) < 1e-6
    (plant,) = sls(chain, graph="plant", horizon=20)
    assert plant.status == "optimal" and plant.extras["qi"] and plant.cost > 1.0 + 1e-4
    assert (plant.links, plant.self_loops) == count_links(chain.plant_adj)
    check = compare_exact_and_simulated(chain, plant.controller)
    assert abs(check["z"]) < 3 and abs(check["control_variate"] - plant.cost) < 1e-9
    (given,) = sls(chain, graph="given")
    assert given.status == "infeasible" and not given.extras["qi"]


def test_truncation_keeps_node_blocks_and_polishes_them(chain):
    from baselines._sparse import GRAD_RTOL, pattern_of
    from codesign import static_gain_cost_and_grad

    designs = get_method("truncated_lqr")(chain, links=[56, 9, 2, 0])
    assert [d.links for d in designs] == [56, 9, 2, 0] and all(d.self_loops == 8 for d in designs)
    for d in designs:
        assert d.status == "optimal", d.message
        K = np.asarray(d.controller.K)
        cost, grad = static_gain_cost_and_grad(chain, K)
        assert np.linalg.norm(grad[pattern_of(K, chain)]) < GRAD_RTOL * cost
    assert abs(designs[0].cost - 1.0) < 1e-9
    assert designs[-1].cost == pytest.approx(get_method("decentralized")(chain)[0].cost, rel=1e-9)


def test_admm_path_on_node_blocks_runs_from_dense_to_no_links(chain):
    """The group (block Frobenius) penalty: whole node blocks leave the gain together."""
    from baselines._sparse import GRAD_RTOL, pattern_of
    from codesign import static_gain_cost_and_grad

    designs = get_method("sparse_admm")(chain, gammas=[1e-9, 1e-5, 1e-3, 1e-1])
    links = [d.links for d in designs]
    assert links[0] >= 50 and links[-1] == 0 and links == sorted(links, reverse=True)
    for d in designs:
        assert d.status == "optimal" and d.self_loops == 8, d.message
        K = np.asarray(d.controller.K)
        cost, grad = static_gain_cost_and_grad(chain, K)
        assert np.linalg.norm(grad[pattern_of(K, chain)]) < GRAD_RTOL * cost
        assert d.links == count_links(chain.node_support(K))[0]


def test_methods_without_node_blocks_record_a_failure(chain):
    """Every built-in handles node blocks; a plug-in that does not say so gets a recorded failure."""
    from codesign.methods import Method, registered_methods

    builtins = [m for m in registered_methods().values() if m.modules[0].split(".")[0] in ("codesign", "baselines")]
    assert len(builtins) >= 14 and all(m.node_blocks for m in builtins)

    def scalar_only(instance, *, seed: int = 0):
        raise AssertionError("never called on node blocks")

    (design,) = Method.from_function(scalar_only, name="scalar_only")(chain)
    assert design.status == "failed" and "several states or inputs" in design.message


def test_a_mass_spring_experiment_runs_end_to_end(tmp_path):
    (tmp_path / "chain.toml").write_text(
        'name = "chain"\n[instances]\nfamily = "mass_spring"\nn = [6]\nseeds = 2\nhorizon = 20\n'
        '[[methods]]\nmethod = "lqr"\n[[methods]]\nmethod = "sparse_admm"\ngrid = { gammas = [[1e-5, 1e-2]] }\n'
        '[[methods]]\nmethod = "gcnn"\nparams = { steps = 20, ensemble = 1, stability_steps = 0 }\n'
        '[[methods]]\nmethod = "grnn_sparse"\nparams = { steps = 20, ensemble = 1, stability_steps = 0, beta = 0.1 }\n')
    result = _run(tmp_path / "chain.toml", tmp_path / "out")
    assert result.exit_code == 0, result.output
    assert "8 runs: 8 computed" in result.output and "failed" not in result.output
    assert "mass_spring, N = 6" in (tmp_path / "out" / "report.md").read_text()


def test_node_maps_are_validated_by_name():
    A, B = np.eye(4) * 0.9, np.eye(4)[:, :2]
    with pytest.raises(ValueError, match="B has 2 columns but there are 4 nodes"):
        Instance.from_matrices(A, B)
    with pytest.raises(ValueError, match="state_nodes must have one entry per state"):
        Instance.from_matrices(A, B, state_nodes=[0, 1], input_nodes=[0, 1])
    with pytest.raises(ValueError, match="input_nodes names node 5"):
        Instance.from_matrices(A, B, state_nodes=[0, 0, 1, 1], input_nodes=[0, 5])
    inst = Instance.from_matrices(A, B, state_nodes=[0, 0, 1, 1], input_nodes=[0, 1])
    assert (inst.nodes, inst.n, inst.m) == (2, 4, 2) and inst.comm_adj.shape == (2, 2)


def test_random_network_follows_the_lqrsp_example():
    from compare.run.families.random_network import random_network_instance

    net = random_network_instance(12, seed=1)
    assert (net.n, net.m, net.nodes) == (24, 12, 12)
    np.testing.assert_array_equal(net.state_nodes, np.repeat(np.arange(12), 2))
    assert count_links(net.plant_adj) == (132, 12)  # every pair is coupled
    comm = net.comm_adj != 0
    assert np.array_equal(comm, comm.T) and all(comm[i].sum() - 1 >= 4 for i in range(12))
    assert net.open_loop_radius > 1  # unstable nodes
    assert abs(get_method("lqr")(net)[0].cost - 1.0) < 1e-9
    local = get_method("decentralized")(net)[0]
    assert local.status == "optimal" and local.links == 0 and local.cost > 1.0
    assert random_network_instance(12, seed=2).A.tolist() != net.A.tolist()
    spec = parse_spec('name = "r"\n[instances]\nfamily = "random_network"\nn = [12]\nseeds = 2\n'
                      '[[methods]]\nmethod = "lqr"\n')
    assert [r.instance["seed"] for r in spec.runs()] == [0, 1] and spec.runs()[0].instance["side"] == np.sqrt(12)


def test_one_experiment_can_join_several_families(tmp_path):
    """``[[instances]]`` lists tables of different families; ``where`` can pick a family."""
    text = (
        'name = "two"\n'
        '[[instances]]\nfamily = "mass_spring"\nn = [4]\nhorizon = 10\n'
        '[[instances]]\nfamily = "random_network"\nn = [6]\nseeds = 2\nhorizon = 10\n'
        '[[methods]]\nmethod = "lqr"\n'
        '[[methods]]\nmethod = "decentralized"\nwhere = { family = ["random_network"] }\n')
    spec = parse_spec(text, base=tmp_path)
    assert spec.instances.families == ("mass_spring", "random_network")
    runs = spec.runs()
    assert [(r.instance["family"], r.method) for r in runs] == [
        ("mass_spring", "lqr"), ("random_network", "lqr"), ("random_network", "decentralized"),
        ("random_network", "lqr"), ("random_network", "decentralized")]
    with pytest.raises(SpecError, match=r"instances\[1\].family: unknown family 'mass'"):
        parse_spec(text.replace('family = "random_network"\nn', 'family = "mass"\nn'), base=tmp_path)
    (tmp_path / "two.toml").write_text(text)
    result = _run(tmp_path / "two.toml", tmp_path / "out")
    assert result.exit_code == 0, result.output
    report = (tmp_path / "out" / "report.md").read_text()
    assert "mass_spring, N = 4" in report and "random_network, N = 6" in report
