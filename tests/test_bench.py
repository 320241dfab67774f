"""`jaxunilat bench`: its reference, its peers, its bookkeeping, and a tiny end-to-end run.

The benchmark's reference (`jaxunilat._bench._peers`) is package code; here it is checked
against this suite's independent references (`reference.py`: scipy with events and the
drag-free closed form). No test asserts on wall-clock time.
"""

from __future__ import annotations

import json
import math
import os
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from helpers import PAPER_Y0
from reference import BallParams, closed_form_reference, parabola

from jaxunilat import bench
from jaxunilat._bench import (
    _goals as _bench_goals,
    _main as _bench,
    _peers as peers,
    _scale as _bench_scale,
    _user as _bench_user,
)
from jaxunilat._cli._main import main

TS = np.linspace(0.0, 2.0, 2001)


def test_bench_reference_agrees_with_the_test_references(ref_ex2):
    ours = peers.reference(peers.Params(), PAPER_Y0, TS)
    assert np.max(np.abs(ours.x - ref_ex2(TS)[0])) <= 1e-10
    np.testing.assert_allclose(ours.entries[:5], ref_ex2.impact_times()[1:6], rtol=0, atol=1e-12)
    # Drag-free: the bench's closed form and its reference against the suite's closed form.
    cf_tests = closed_form_reference(BallParams.table1(2, drag=None), PAPER_Y0, 2.0)(TS)[0]
    cf_ours = peers.closed_form_drag_free(peers.Params(drag=None), PAPER_Y0, TS)
    assert np.max(np.abs(cf_ours.x - cf_tests)) <= 1e-12
    assert np.max(np.abs(peers.reference(peers.Params(drag=None), PAPER_Y0, TS).x - cf_tests)) <= 1e-10


def test_numpy_rk4_peer_matches_the_parabola():
    # Drag-free free flight from mid-air (no contact in 0.2 s): RK4 is exact for a parabola.
    p = peers.Params(drag=None)
    ts = np.linspace(0.0, 0.2, 201)
    run = peers.numpy_rk4(p, (0.0, 1.0), ts, 1e-4)
    np.testing.assert_allclose(run.x, parabola(0.0, 1.0, 9.81, ts)[0], rtol=0, atol=1e-13)
    with pytest.raises(ValueError, match="must divide"):
        peers.numpy_rk4(p, (0.0, 1.0), ts, 3e-4)


def test_scipy_peers_converge_to_the_reference(ref_ex2):
    p = peers.Params()
    x_ref = ref_ex2(TS)[0]
    loose = peers.solve_events(p, PAPER_Y0, TS, method="DOP853", rtol=1e-6, atol=1e-6)
    tight = peers.solve_events(p, PAPER_Y0, TS, method="DOP853", rtol=1e-11, atol=1e-11)
    e_loose, e_tight = (np.max(np.abs(r.x - x_ref)) for r in (loose, tight))
    assert e_tight <= 1e-8 and e_tight < e_loose / 100
    plain = peers.solve_no_events(p, PAPER_Y0, TS, method="LSODA", rtol=1e-8, atol=1e-8)
    assert np.max(np.abs(plain.x - x_ref)) <= 1e-4


def test_count_equations_counts_nested_jaxprs():
    flat = jax.make_jaxpr(lambda x: jnp.sin(x) + 1.0)(1.0)
    assert _bench.count_equations(flat) == 2
    loop = jax.make_jaxpr(lambda x: jax.lax.fori_loop(0, 3, lambda i, y: jnp.sin(y) * 2.0, x))(1.0)
    assert _bench.count_equations(loop) > len(loop.jaxpr.eqns) + 1


def _row(method, error, wall, peer):
    return {"method": method, "setting": "s", "error": error, "wall_s": wall, "peer": peer}


def test_ratio_goal_takes_the_fastest_run_within_the_error_bound():
    rows = [
        _row("mine", 5e-10, 0.004, False),
        _row("mine", 5e-8, 0.001, False),  # faster but not accurate enough
        _row("scipy DOP853 + events", 8e-10, 0.050, True),
        _row("scipy LSODA + events", 9e-10, 0.040, True),
        _row("scipy RK45 + events", 2e-9, 0.010, True),  # fastest peer, not accurate enough
    ]
    goal = _bench_goals._ratio_goal("time_ratio_1e9", rows, 1e-9)
    assert goal["value"] == pytest.approx(0.004 / 0.040)
    assert goal["vs_dop853_events"] == pytest.approx(0.004 / 0.050)
    assert goal["met"] is False  # 0.1 > 1/20
    assert _bench_goals._ratio_goal("time_ratio_1e9", rows[1:2] + rows[2:], 1e-9)["value"] is None
    # The compiled loop's runs are peers too: the fastest accurate one is the best peer.
    compiled = [
        _row("Numba DOP853 + events", 7e-10, 0.002, True),
        _row("Numba DOP853 + events", 3e-9, 0.001, True),
    ]
    result = {"work_precision": rows, "compiled_loop": {"rows": compiled}}
    goal = _bench_goals._ratio_goal("time_ratio_1e9", _bench_goals.runs(result), 1e-9)
    assert goal["value"] == pytest.approx(0.004 / 0.002) and goal["best_peer"].startswith("Numba")
    assert _bench_goals.runs({"work_precision": rows}) == rows  # without Numba: scipy's and NumPy's


def _user_section(sim_ratio=0.6):
    return {
        "vmap_against_rows": {
            "n": 10,
            "kappa_range": [8e3, 1.2e4],
            "device": "cpu:0",
            "scene": "s",
            "ratio": 1.8,
            "vmap_per_row_s": 1.8e-4,
            "sequential_per_row_s": 1e-4,
        },
        "reverse_against_forward": {
            "ratio": 4.0,
            "loss": "l",
            "scene": "s",
            "forward_s": 1e-3,
            "reverse_s": 4e-3,
            "forward_mode_ratio": 1.8,
        },
        "command_line": {
            "import_s": 1.0,
            "commands": {
                "simulate": {"first_s": 4.0, "second_s": 4.0 * sim_ratio, "ratio": sim_ratio},
                "identify": {"first_s": 3.0, "second_s": 1.5, "ratio": 0.5},
                "reproduce": {"status": "skipped at size quick (slow for this size)"},
            },
        },
    }


def test_user_goals_take_their_values_from_the_user_section():
    goals = _bench_goals.user_goals(_user_section())
    keys = ("user_vmap_ratio", "user_grad_ratio", "cli_second_run")
    assert [goals[k]["value"] for k in keys] == [1.8, 4.0, 0.6]
    assert [goals[k]["met"] for k in keys] == [False, True, False]
    for goal in goals.values():
        assert {"value", "target", "met", "unit", "measured", "reproduce"} <= set(goal)
    assert goals["user_grad_ratio"]["forward_mode_ratio"] == 1.8
    assert goals["cli_second_run"]["by_command"]["identify"] == 0.5
    assert goals["cli_second_run"]["by_command"]["reproduce"].startswith("skipped")
    # The outputs under vmap: 2001 save times at 0.5x the throughput of 2 is a time ratio of 2, missed.
    with_outputs = _user_section()
    with_outputs["vmap_outputs"] = {
        "rule": "lockstep",
        "n": 8,
        "samples": [2, 2001],
        "throughput_traj_per_s": [1000.0, 500.0],
        "ratio": 0.5,
        "time_ratio": 2.0,
        "scene": "s",
    }
    goal = _bench_goals.user_goals(with_outputs)["vmap_outputs_ratio"]
    assert goal["value"] == 2.0 and goal["met"] is False and abs(goal["target"] - 1 / 0.7) < 1e-12
    # A failed command line run: no value, not met.
    failed = _user_section()
    failed["command_line"]["commands"]["simulate"] = {"first_s": 4.0, "second_s": None, "ratio": None}
    assert _bench_goals.user_goals(failed)["cli_second_run"]["met"] is False
    # A section skipped at this size: no value, not met, and the goal says why.
    skipped = _user_section()
    skipped["reverse_against_forward"] = {"status": "skipped at size tiny", "ratio": None}
    goal = _bench_goals.user_goals(skipped)["user_grad_ratio"]
    assert goal["value"] is None and goal["met"] is False and goal["status"] == "skipped at size tiny"


def test_old_bench_json_reads_with_todays_goal_keys(tmp_path):
    """A bench.json written before the goals had names (P1-P5, P7-P10) loads with today's
    keys, in its order, the goals' contents untouched; the table prints it."""
    old_goals = {
        key: {"value": 0.5, "target": 1.0, "met": True, "unit": "u"}
        for key in ("P1", "P2", "P3", "P4", "P5", "P7", "P8", "P9", "P10")
    }
    old_goals["P3"].update(ratio_vs_scipy_loop=400.0, ratio_target=300.0)
    old = {"size": "quick", "goals": old_goals, "work_precision": []}
    path = tmp_path / "bench.json"
    path.write_text(json.dumps(old))
    new = bench.load(path)
    assert list(new["goals"]) == [
        "time_ratio_1e9",
        "time_ratio_1e6",
        "throughput",
        "gradient_ratio",
        "compile_time",
        "user_vmap_ratio",
        "user_grad_ratio",
        "cli_second_run",
        "default_user_ratio",
    ]
    # Goals added after the names: absent from an old file.
    assert set(new["goals"]) == set(_bench_goals.GOALS) - {"vmap_outputs_ratio"}
    assert new["goals"]["throughput"] == old_goals["P3"] and new["size"] == "quick"
    assert bench.upgrade(new) == new  # today's keys stay as they are
    assert old["goals"] is old_goals and "P1" in old_goals  # the argument is not changed
    table = bench.goal_table(old)
    assert "\nthroughput " in table and "ratio against the scipy loop" in table
    assert not any(line.startswith("P") for line in table.splitlines())


def test_identify_rows_are_listed_and_skip_at_the_tiny_size():
    """The bench's identification rows are named in its table (no plugin lookup), and at
    the tiny size they skip at once."""
    assert set(_bench.ROWS) == {"identification", "joint_fit"}
    assert all(target.startswith("jaxunilat.identify._bench:") for target in _bench.ROWS.values())
    rows = _bench._identify_rows(_bench.SIZES["tiny"], print)
    assert rows["identification"] == {"status": "skipped at size tiny", "rows": []}
    assert rows["joint_fit"] == {"status": "skipped at size tiny"}


def test_command_line_children_get_a_new_cache_and_the_users_environment(monkeypatch):
    monkeypatch.setenv("JAXUNILAT_NO_CACHE", "1")  # as in this suite
    flag = "--xla_force_host_platform_device_count=7"
    monkeypatch.setenv("XLA_FLAGS", f"--xla_a=1 {flag}")
    monkeypatch.setattr(_bench_scale, "ADDED_XLA_FLAG", flag)
    env = _bench_user._child_env("/tmp/some-cache")
    assert "JAXUNILAT_NO_CACHE" not in env
    assert env["JAXUNILAT_CACHE_DIR"] == "/tmp/some-cache"
    assert env["XLA_FLAGS"] == "--xla_a=1"
    # The folder that holds the package (jaxunilat/_bench/_user.py: three levels up).
    assert env["PYTHONPATH"].split(os.pathsep)[0] == str(Path(_bench_user.__file__).parents[2])


def test_user_rows_span_kappa_plus_minus_20_percent():
    kappas = _bench_user.kappa_rows(5)
    assert kappas[0] == pytest.approx(0.8e4) and kappas[-1] == pytest.approx(1.2e4)
    assert kappas[2] == pytest.approx(1e4)


def test_bench_without_scipy_fails_with_one_line(monkeypatch, tmp_path, capsys):
    monkeypatch.setitem(__import__("sys").modules, "scipy", None)  # `import scipy` raises ImportError
    code = main(["bench", "--quick", "--out", str(tmp_path / "b")])
    err = capsys.readouterr().err.strip()
    assert code == 2
    assert len(err.splitlines()) == 1
    assert 'pip install "jaxunilat[bench]"' in err
    assert not (tmp_path / "b").exists()


def test_compiled_peer_without_numba_is_one_line(monkeypatch):
    from jaxunilat._bench import _compiled

    monkeypatch.setattr(_compiled, "numba", None)
    lines, rows = [], [_row("mine", 1e-9, 0.001, False)]
    out = _compiled.bench_section((1e-8,), 4, 1e-9, TS, None, rows, None, lines.append)
    assert out["rows"] == [] and out["throughput"] == [] and out["peer_wrong_rows"] is None
    assert len(lines) == 1 and "numba is not installed" in lines[0]
    assert rows[0]["vs_compiled"] is None


@pytest.mark.slow
def test_bench_tiny_end_to_end(tmp_path, capsys):
    """Every section at its smallest; the users' code in fresh processes and its reverse-mode
    gradient are skipped at this size (`test_command_line_pair_*` runs the processes' pair)."""
    out = tmp_path / "bench"
    assert main(["bench", "--size", "tiny", "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    for key in _bench_goals.GOALS:
        assert f"\n{key} " in printed
    for name in ("work_precision.png", "throughput.png"):
        assert (out / name).stat().st_size > 10_000
    result = json.loads((out / "bench.json").read_text())

    # Schema.
    assert {"machine", "goals", "work_precision", "throughput"} <= set(result)
    assert list(result["goals"]) == list(_bench_goals.GOALS)
    for goal in result["goals"].values():
        assert {"value", "target", "met", "unit"} <= set(goal)
        assert isinstance(goal["met"], bool)
    for row in result["work_precision"]:
        assert {"method", "setting", "error", "wall_s", "compile_s", "peer"} <= set(row)
    for row in result["throughput"]:
        assert {"method", "n", "traj_per_s", "peak_mem_mb"} <= set(row)
    methods = {r["method"] for r in result["work_precision"]}
    assert {"scipy DOP853 + events", "NumPy RK4 loop", "event (tsit5)", "rk4, exact H"} <= methods

    # The figures it reports are right, against independent checks.
    assert result["reference_check"]["max_dx_m"] <= 1e-10  # reference vs drag-free closed form
    rows = {(r["method"], r["setting"]): r for r in result["work_precision"]}
    # RK4 with the exact Heaviside at dt = 1e-4: the same error for the JAX and the NumPy loop.
    assert rows[("rk4, exact H", "dt 0.0001")]["error"] == pytest.approx(
        rows[("NumPy RK4 loop", "dt 0.0001")]["error"], rel=1e-6
    )
    assert rows[("event (tsit5)", "tol 1e-10")]["error"] <= 1e-8
    assert rows[("scipy DOP853 + events", "tol 1e-12")]["error"] <= 1e-9
    assert result["throughput_checks"]["max_error_m"] <= 1e-8
    assert result["no_retrace"]["ok"] is True
    scenes = {r["scene"]: r for r in result["static_structure"]}
    assert scenes["drag None"]["equations"] < scenes["drag = 0"]["equations"]
    # Same physics: the same end state. (A drag term present with value 0 still makes the
    # event mode end a piece at every apex and deepest point, its kink: a few more steps.)
    assert scenes["drag None"]["x_end_m"] == pytest.approx(scenes["drag = 0"]["x_end_m"], abs=1e-8)
    assert (
        abs(scenes["drag None"]["steps"] - scenes["drag = 0"]["steps"]) <= 0.05 * scenes["drag None"]["steps"]
    )
    # The tiny size leaves out the reverse-mode gradient (its compile is the slowest part;
    # tests/test_event_mode.py checks event-mode gradients against FD of the reference) and
    # the 2-device subprocess (tests/test_sweep.py runs it).
    assert result["gradient"]["losses"] == [] and result["goals"]["gradient_ratio"]["value"] is None
    assert result["scale_out"]["rows"] == []
    # time_ratio_1e9 recomputed from the rows.
    ok = [r for r in _bench_goals.runs(result) if r["error"] is not None and r["error"] <= 1e-9]
    mine = min(r["wall_s"] for r in ok if not r["peer"])
    best_peer = min(r["wall_s"] for r in ok if r["peer"])
    assert math.isclose(result["goals"]["time_ratio_1e9"]["value"], mine / best_peer, rel_tol=1e-12)
    assert result["goals"]["throughput"]["ratio_vs_scipy_loop"] > 0
    # The compiled-loop peer (Numba), when installed: accurate, with the ratio columns.
    compiled = result["compiled_loop"]
    if compiled["status"] == "measured":
        tight = {r["setting"]: r for r in compiled["rows"]}["tol 1e-12"]
        assert tight["error"] <= 1e-9 and tight["crossings"] >= 10 and tight["accepted"] > 0
        assert all({"vs_scipy", "vs_compiled"} <= set(r) for r in result["work_precision"] if not r["peer"])
        assert [r["threads"] for r in compiled["throughput"]][0] == 1
        # Every row of its throughput runs checked against jaxunilat's: none wrong.
        assert compiled["peer_wrong_rows"] == 0 and compiled["peer_check"]["n"] == 4
        assert all(r["valid"] and r["peer_wrong_rows"] == 0 for r in compiled["throughput"])
    # identify's registered rows, skipped at this size.
    assert result["identification"]["status"].startswith("skipped") and result["identification"]["rows"] == []
    assert result["joint_fit"]["status"].startswith("skipped")

    # The users' code: plain vmap measured (no assertion on the timings themselves); the
    # gradient and the fresh processes skipped at this size, their goals without a value.
    goal = result["goals"]["user_vmap_ratio"]
    assert {"measured", "reproduce"} <= set(goal)
    assert math.isfinite(goal["value"]) and goal["value"] > 0
    user = result["user"]
    assert "jax.jit(jax.vmap(f))" in user["code"] and "jax.grad(loss)" in user["code"]
    vm = user["vmap_against_rows"]
    assert vm["n"] == 4
    assert {"vmap_s", "sequential_s", "vmap_per_row_s", "sequential_per_row_s", "ratio"} <= set(vm)
    assert vm["max_abs_difference_m"] <= 1e-9  # vmapped and one by one: the same rows
    for key, section in (
        ("user_grad_ratio", user["reverse_against_forward"]),
        ("default_user_ratio", user["default_user"]),
    ):
        assert section["status"] == "skipped at size tiny"
        assert result["goals"][key]["value"] is None and result["goals"][key]["status"] == section["status"]
    assert result["goals"]["cli_second_run"]["value"] is None
    assert all(row["status"].startswith("skipped") for row in user["command_line"]["commands"].values())


def test_command_line_pair_runs_twice_in_fresh_processes_on_one_new_cache(monkeypatch):
    """cli_second_run's machinery on a fast command (`jaxunilat --version`): two fresh
    processes, their walls and the ratio; a failing command is reported, not raised."""
    monkeypatch.setitem(_bench_user.CLI_COMMANDS, "version", ("--version",))
    lines = []
    row = _bench_user._cli_pair("version", lines.append)
    assert row["ok"] is True and [r["returncode"] for r in row["runs"]] == [0, 0]
    assert row["command"] == "jaxunilat --version"
    assert row["ratio"] == pytest.approx(row["second_s"] / row["first_s"])
    assert "first" in lines[0] and "second" in lines[0]
    monkeypatch.setitem(_bench_user.CLI_COMMANDS, "bad", ("no-such-command",))
    row = _bench_user._cli_pair("bad", lines.append)
    assert row["ok"] is False and row["ratio"] is None and row["runs"][0]["returncode"] == 2
    assert "failed" in lines[-1]


def test_accelerator_section_on_an_accelerator_and_skipped_on_a_cpu(monkeypatch):
    """On a CPU backend the section says it was skipped; where the default backend is an
    accelerator (stood in for by the CPU reporting "gpu") it measures sweeps at each N,
    one call's latency on the device and by default, and puts the compiled loop's rows
    beside them."""
    from jaxunilat._bench import _accelerator

    lines = []
    assert _accelerator.accelerator_section(lines.append)["status"].startswith("skipped")
    monkeypatch.setattr(jax, "default_backend", lambda: "gpu")
    compiled = {
        "throughput": [{"method": "compiled loop, prange", "n": 8, "traj_per_s": 1.0, "wrong_rows": 0}]
    }
    out = _accelerator.accelerator_section(lines.append, ns=(4, 8), repeats=2, fit=False, compiled=compiled)
    assert out["status"] == "measured" and [r["n"] for r in out["sweep"]] == [4, 8]
    assert all(r["all_ok"] and r["traj_per_s"] > 0 for r in out["sweep"])
    assert out["latency"]["accelerator_s"] > 0 and out["latency"]["default_s"] > 0
    assert out["compiled_loop"][0]["method"] == "compiled loop, prange"
    assert out["fit"] == {"status": "skipped at this size"}
