"""The benchmark's goals: values from the measured sections, notes on missed ones.

The goals (targets in `GOALS`), by key:

- `time_ratio_1e9`, `time_ratio_1e6`: wall time of the project's fastest run against the
  best peer's in the same run (scipy, NumPy and the compiled loop's work-precision rows),
  among the runs with an error of at most 1e-9 m (1e-6 m);
- `throughput`: trajectories per second at the largest batch (and the ratio against a
  scipy loop);
- `gradient_ratio`: gradient / forward time of the bench's losses, in the cheaper AD mode;
- `compile_time`: compile time of the event-mode forward scene (s);

and, measured on code as users write it (`_user.py`):

- `user_vmap_ratio`: plain `jax.jit(jax.vmap(f))` against rows one by one;
- `vmap_outputs_ratio`: 2001 save times against 2 under lockstep `jax.vmap`;
- `user_grad_ratio`: `jax.grad` against a forward solve;
- `cli_second_run`: the command line's second run against its first;
- `default_user_ratio`: a plain script that never calls `use_loop_kernels` against the
  tuned one (each a fresh process).

Where a goal is missed, `notes` says why and what would close it, from the run's own
figures. `bench.json` files written before the goals had names keyed them P1–P5, P7–P10;
`upgrade` renames those keys (`OLD_KEYS`).
"""

from __future__ import annotations

GOALS = {
    "time_ratio_1e9": dict(target=1 / 20, unit="time ratio (project / best peer) at error <= 1e-9 m"),
    "time_ratio_1e6": dict(target=1 / 50, unit="time ratio (project / best peer) at error <= 1e-6 m"),
    "throughput": dict(
        target=1e4, unit="trajectories/s at the largest N, error <= 1e-8 m", ratio_target=300.0
    ),
    "gradient_ratio": dict(
        target=5.0,
        unit="gradient time / forward time (worst of the two losses, in the cheaper AD mode for (kappa, k_r))",
    ),
    "compile_time": dict(target=3.0, unit="s, compile time of the event-mode forward scene"),
    "user_vmap_ratio": dict(
        target=1.2, unit="time ratio jax.jit(jax.vmap(f)) / sweep(f, batch_size=1), N rows, one device"
    ),
    "user_grad_ratio": dict(
        target=5.0, unit="time ratio jax.jit(jax.grad(loss)) / jax.jit(loss), misfit in (kappa, k_r)"
    ),
    "cli_second_run": dict(
        target=0.5, unit="wall ratio second / first `jaxunilat simulate ball --solver event`, new cache"
    ),
    "vmap_outputs_ratio": dict(
        target=1 / 0.7,
        unit="time ratio 2001 / 2 save times, throughput scene under lockstep jax.vmap "
        "(a throughput ratio >= 0.7)",
    ),
    "default_user_ratio": dict(
        target=1.2,
        unit="time ratio default user / tuned (no use_loop_kernels call / with it), fresh processes, "
        "worse of jax.jit(f) and jax.jit(jax.vmap(f))",
    ),
}
TIGHT_ERROR, LOOSE_ERROR, THROUGHPUT_ERROR = 1e-9, 1e-6, 1e-8


def _best(rows, peer: bool, max_error: float):
    ok = [r for r in rows if r["peer"] == peer and r["error"] <= max_error]
    return min(ok, key=lambda r: r["wall_s"]) if ok else None


def _ratio_goal(key, rows, max_error):
    mine, theirs = _best(rows, False, max_error), _best(rows, True, max_error)
    dop = [
        r for r in rows if r["peer"] and r["method"] == "scipy DOP853 + events" and r["error"] <= max_error
    ]
    dop = min(dop, key=lambda r: r["wall_s"]) if dop else None
    goal = {"target": GOALS[key]["target"], "unit": GOALS[key]["unit"]}
    if mine is None or theirs is None:
        return {
            **goal,
            "value": None,
            "met": False,
            "note": "no project run or no peer reached the error bound",
        }
    value = mine["wall_s"] / theirs["wall_s"]
    return {
        **goal,
        "value": value,
        "met": value <= goal["target"],
        "project": f"{mine['method']}, {mine['setting']}: {1e3 * mine['wall_s']:.2f} ms",
        "best_peer": f"{theirs['method']}, {theirs['setting']}: {1e3 * theirs['wall_s']:.2f} ms",
        "vs_dop853_events": None if dop is None else mine["wall_s"] / dop["wall_s"],
    }


def runs(result: dict) -> list[dict]:
    """Every work-precision run of a `bench.json` dictionary: the project's, scipy's and
    NumPy's (`work_precision`), and the compiled loop's (`compiled_loop`, Numba), often the
    fastest peer."""
    return list(result["work_precision"]) + list(result.get("compiled_loop", {}).get("rows", []))


def goals(result: dict) -> dict:
    """Every goal from the measured sections, each with value, target, met, unit and a note."""
    wp = runs(result)
    out = {
        "time_ratio_1e9": _ratio_goal("time_ratio_1e9", wp, TIGHT_ERROR),
        "time_ratio_1e6": _ratio_goal("time_ratio_1e6", wp, LOOSE_ERROR),
    }
    tp = [r for r in result["throughput"] if not r["peer"]]
    loop = [r for r in result["throughput"] if r["peer"]]
    largest = max(r["n"] for r in tp)
    big = max((r for r in tp if r["n"] == largest), key=lambda r: r["traj_per_s"])
    ratio = big["traj_per_s"] / loop[0]["traj_per_s"] if loop else None
    accurate = result["throughput_checks"]["max_error_m"] <= THROUGHPUT_ERROR
    out["throughput"] = {
        "target": GOALS["throughput"]["target"],
        "unit": GOALS["throughput"]["unit"],
        "value": big["traj_per_s"],
        "n": big["n"],
        "strategy": big.get("strategy"),
        "devices": big.get("devices"),
        "ratio_vs_scipy_loop": ratio,
        "ratio_target": GOALS["throughput"]["ratio_target"],
        "max_error_m": result["throughput_checks"]["max_error_m"],
        "met": bool(
            accurate
            and big["traj_per_s"] >= GOALS["throughput"]["target"]
            and ratio is not None
            and ratio >= 300
        ),
    }
    losses = result["gradient"]["losses"]
    # The worst loss in each mode (reverse: jax.grad; forward: jax.jacfwd with
    # autodiff="forward"); gradient_ratio is the cheaper mode, the way to take a gradient in few parameters.
    by_mode = {}
    for row in losses:
        mode = row.get("mode", "reverse")
        by_mode[mode] = max(by_mode.get(mode, 0.0), row["ratio"])
    best = min(by_mode, key=by_mode.get) if by_mode else None
    out["gradient_ratio"] = {
        "target": GOALS["gradient_ratio"]["target"],
        "unit": GOALS["gradient_ratio"]["unit"],
        "value": None if best is None else by_mode[best],
        "mode": best,
        "by_mode": by_mode,
        "met": best is not None and by_mode[best] <= GOALS["gradient_ratio"]["target"],
    }
    compile_s = result["compile_s"].get("event tsit5")
    out["compile_time"] = {
        "target": GOALS["compile_time"]["target"],
        "unit": GOALS["compile_time"]["unit"],
        "value": compile_s,
        "met": compile_s is not None and compile_s <= GOALS["compile_time"]["target"],
        "gradient_compile_s": max((r["gradient_compile_s"] for r in losses), default=None),
        "gradient_compile_s_by_mode": {
            mode: max(r["gradient_compile_s"] for r in losses if r.get("mode", "reverse") == mode)
            for mode in by_mode
        },
    }
    if "user" in result:
        out.update(user_goals(result["user"]))
    for key, note in notes(result, out).items():
        out[key]["note"] = note
    return out


def user_goals(user: dict) -> dict:
    """The goals measured on the users' code, from the `user` section (`_user.py`): value,
    target, met, what was measured and how to reproduce it."""
    vm, grad, cli = user["vmap_against_rows"], user["reverse_against_forward"], user["command_line"]
    code = "the Python in bench.json's user.code"
    out = {
        "user_vmap_ratio": {
            "value": vm["ratio"],
            "measured": f"per-row time of jax.jit(jax.vmap(f)) over N = {vm['n']} values of kappa "
            f"({vm['kappa_range'][0]:g} to {vm['kappa_range'][1]:g} N/m) against jaxunilat.sweep(f, kappas, "
            f"batch_size=1) on the same device ({vm['device']}), warm medians; {vm['scene']}",
            "n": vm["n"],
            "vmap_per_row_s": vm["vmap_per_row_s"],
            "sequential_per_row_s": vm["sequential_per_row_s"],
            "reproduce": f"{code} (user_vmap_ratio, N = {vm['n']})",
        },
        "user_grad_ratio": {
            "value": grad.get("ratio"),
            "measured": f"jax.jit(jax.grad(loss)) against jax.jit(loss), warm medians; loss: "
            f"{grad.get('loss', grad.get('status'))}; {grad.get('scene', '')}",
            "forward_s": grad.get("forward_s"),
            "reverse_s": grad.get("reverse_s"),
            "forward_mode_ratio": grad.get("forward_mode_ratio"),
            "reproduce": f"{code} (user_grad_ratio)",
        },
    }
    sim = cli["commands"].get("simulate", {})
    out["cli_second_run"] = {
        "value": sim.get("ratio"),
        "measured": "wall time of `jaxunilat simulate ball --solver event` run twice, each a fresh process, "
        "sharing a new empty compilation cache (JAXUNILAT_CACHE_DIR); second / first",
        "first_s": sim.get("first_s"),
        "second_s": sim.get("second_s"),
        "import_s": cli.get("import_s"),
        "by_command": {
            name: row.get("ratio") if "ratio" in row else row.get("status")
            for name, row in cli["commands"].items()
        },
        "reproduce": "export JAXUNILAT_CACHE_DIR=$(mktemp -d); time jaxunilat simulate ball --solver event; "
        "time jaxunilat simulate ball --solver event",
    }
    if "vmap_outputs" in user:
        vo = user["vmap_outputs"]
        out["vmap_outputs_ratio"] = {
            "value": vo["time_ratio"],
            "measured": f"{vo['rule']}, N = {vo['n']}: {vo['throughput_traj_per_s'][0]:.0f} traj/s at "
            f"{vo['samples'][0]} save times, {vo['throughput_traj_per_s'][1]:.0f} at {vo['samples'][1]} "
            f"(throughput ratio {vo['ratio']:.2f}); {vo['scene']}",
            "reproduce": "jaxunilat bench (user.vmap_outputs)",
        }
    if "default_user" in user:
        out["default_user_ratio"] = _default_user_goal(user["default_user"])
    for key, section in (("user_grad_ratio", grad), ("default_user_ratio", user.get("default_user", {}))):
        if "status" in section:  # skipped at this size
            out[key]["status"] = section["status"]
    for key, goal in out.items():
        value = goal["value"]
        out[key] = {
            "target": GOALS[key]["target"],
            "unit": GOALS[key]["unit"],
            **goal,
            "met": value is not None and value <= GOALS[key]["target"],
        }
    return out


def _default_user_goal(row: dict) -> dict:
    """default_user_ratio from the `default_user` section: default / tuned, the worse of its two ratios."""
    default, tuned = row.get("default", {}), row.get("tuned", {})
    out = {
        "value": row.get("ratio"),
        "measured": f"{row.get('how', '')}; {row.get('scene', '')}",
        "n": row.get("n"),
        "one_ratio": row.get("one_ratio"),
        "vmap_ratio": row.get("vmap_ratio"),
        "default_one_s": default.get("one_s"),
        "tuned_one_s": tuned.get("one_s"),
        "reproduce": "the Python in bench.json's user.default_user.default_code, in a fresh process "
        "(tuned: with ju.use_loop_kernels() after the imports)",
    }
    if row.get("ratio") is not None:
        n = row["n"]
        out["default_traj_per_s"] = n / default["vmap_s"]
        out["tuned_traj_per_s"] = n / tuned["vmap_s"]
        out["default_loop_kernel_bytes"] = default.get("loop_kernel_bytes")
        out["default_warnings"] = default.get("warnings")
    return out


def notes(result: dict, out: dict) -> dict:
    """Why a goal is missed and what would close it, from this run's own figures."""
    fit = result["profile"].get("per_step_fit")
    notes = {}
    kernels = result["machine"].get("loop_kernel_bytes") is not None
    if fit:
        step_us, fixed_ms = 1e6 * fit["per_step_s"], 1e3 * fit["fixed_s"]
        cost = (
            f"the event mode costs about {fixed_ms:.2f} ms per call (the intercept of wall = fixed + "
            "per-step cost x steps over its tolerances: validation and dispatch in Python, the hand-over "
            "of a program with more than 8 thunks to XLA:CPU's thread pool, the loop's set-up, the "
            f"outputs at the 2001 save times) plus {step_us:.2f} us per step"
        )
    else:
        cost = "the event mode's per-step cost dominates"
    if not kernels:
        cost += (
            "; this run had XLA's default CPU options, where every step pays ~100 thunk launches "
            "(5-8 us): import jaxunilat before JAX computes (it sets the option), or unset JAXUNILAT_NO_LOOP_KERNELS"
        )
    for key in ("time_ratio_1e9", "time_ratio_1e6"):
        if not out[key]["met"]:
            notes[key] = (
                f"missed: {cost}. What would close it: less fixed cost per call (the Python side of "
                "simulate and jax.jit's dispatch are ~0.1 ms together; the closed-form flight at 2001 "
                "save times is 3 transcendental functions each), or fewer, larger calls (sweep)."
            )
    if not out["throughput"]["met"]:
        big = out["throughput"]
        tp = [r for r in result["throughput"] if not r["peer"] and r["n"] == big["n"]]
        per = ", ".join(
            f"{r['strategy']} on {r['devices']} device(s) {r['traj_per_s']:.0f} traj/s" for r in tp
        )
        notes["throughput"] = (
            f"missed: at N = {big['n']}: {per}; {cost}. Rows one by one cost one loop plus the outputs at "
            "2001 save times each (3 transcendental functions per save time in flight); vmapped rows run in "
            "lockstep behind the slowest, with every cond's branches. What would close it: more cores "
            "(the sweep shards rows over every device), or fewer save times per row."
        )
    if not out["gradient_ratio"]["met"] and out["gradient_ratio"]["value"] is not None:
        modes = ", ".join(f"{mode} {ratio:.1f}x" for mode, ratio in out["gradient_ratio"]["by_mode"].items())
        notes["gradient_ratio"] = (
            f"missed ({modes}): in forward mode (jax.jacfwd with autodiff='forward') each parameter's tangent "
            "rides along the loop; reverse mode (jax.grad) is an equinox checkpointed while loop with every "
            "step a checkpoint, whose backward pass runs every step's VJP without the loop kernels. What "
            "would close it: an adjoint per smooth segment with jump conditions at the located events."
        )
    if not out["compile_time"]["met"]:
        eq = [r["equations"] for r in result["static_structure"] if r["scene"] in ("drag on", "drag = 0")]
        size = f" ({eq[0]} equations)" if eq else ""
        notes["compile_time"] = (
            f"missed: the event-mode graph{size} unrolls the RK stages (in the loop, and again for the "
            "outputs at the save times), the dense interpolant, the sub-grid crossing checks and the Newton "
            "root finder; what would close it: a smaller graph, or the persistent compilation cache "
            "(jax.config.update('jax_compilation_cache_dir', ...)) across runs."
        )
    notes.update(_user_notes(result, out))
    return notes


def _user_notes(result: dict, out: dict) -> dict:
    """Notes on the missed goals of the users' code, from the run's own figures."""
    notes = {}
    if "user" not in result:
        return notes
    user = result["user"]
    # `goals` added them from the same section; a value of None (a failed command) has no figures.
    missed = {
        key
        for key in ("user_vmap_ratio", "user_grad_ratio", "cli_second_run", "default_user_ratio")
        if key in out and not out[key]["met"] and out[key]["value"] is not None
    }
    branches = result.get("profile", {}).get("cond_branches")
    if "user_vmap_ratio" in missed:
        vm = user["vmap_against_rows"]
        notes["user_vmap_ratio"] = (
            f"missed: {1e6 * vm['vmap_per_row_s']:.1f} us/row vmapped against {1e6 * vm['sequential_per_row_s']:.1f} "
            f"us/row one by one ({vm.get('batching', 'batch')} rule under vmap; on a CPU simulate's rule "
            "runs vmapped rows one by one, JAXUNILAT_VMAP=batch or another backend batches them). "
            "Vmapped rows run in lockstep until the slowest row's last step, every cond "
            f"runs all its branches (the step loop's: {branches}), and a vmapped loop touches every row's "
            "bytes per step, so a large enough batch (N x a row's tens of KiB > 1 MiB) is no longer one "
            "kernel under use_loop_kernels(). What would close it: fewer, cheaper branches in the step "
            "loop under vmap (the rare paths' work only where a row needs it)."
        )
    if "user_grad_ratio" in missed:
        grad = user["reverse_against_forward"]
        notes["user_grad_ratio"] = (
            f"missed: jax.grad {out['user_grad_ratio']['value']:.1f}x the forward solve, jax.jacfwd with "
            f"autodiff='forward' {grad['forward_mode_ratio']:.1f}x. Reverse mode differentiates an equinox "
            "checkpointed while loop, every step a checkpoint that the backward pass reads back (one loop "
            "kernel on a CPU, as long as nothing in it is a scatter). What would close it: an adjoint per "
            "smooth segment with jump conditions at the located events (or forward mode when there are "
            "few parameters)."
        )
    if "cli_second_run" in missed:
        cli = out["cli_second_run"]
        floor = (
            ""
            if cli["import_s"] is None
            else f"; a process that only imports jaxunilat takes {cli['import_s']:.2f} s"
        )
        notes["cli_second_run"] = (
            f"missed: first {cli['first_s']:.2f} s, second {cli['second_s']:.2f} s{floor}. With the caches "
            "the second run still starts Python, imports JAX, and loads the kept program (the executable "
            "cache) or traces and lowers it to find its compilation-cache key. What would close it: less "
            "import work (jax and diffrax take most of it)."
        )
    if "default_user_ratio" in out:
        notes["default_user_ratio"] = _default_user_note(
            out["default_user_ratio"], "default_user_ratio" in missed
        )
    return notes


def _default_user_note(goal: dict, missed: bool) -> str:
    """What default_user_ratio found: where the default user loses against the tuned one, and why."""
    if goal["value"] is None:
        return goal.get("status") or "not measured: a script failed (see user.default_user in bench.json)"
    kernels = goal.get("default_loop_kernel_bytes")
    found = (
        f"jax.jit(f) {goal['one_ratio']:.2f}x, jax.jit(jax.vmap(f)) {goal['vmap_ratio']:.2f}x the tuned "
        f"script; the plain script ran with loop kernels of {kernels} bytes"
        if kernels is not None
        else "the plain script ran without the loop-kernel option"
    )
    if not missed:
        return f"met: {found} (import jaxunilat sets XLA's loop-kernel option; JAXUNILAT_NO_LOOP_KERNELS=1 opts out)."
    return (
        f"missed: {found}. Without the option each event-mode step launches ~100 separate kernels "
        "(5-8 us). What would close it: the option on at import (is JAXUNILAT_NO_LOOP_KERNELS set, or did "
        "JAX start its backend before the import?), or a step loop that XLA:CPU runs fast without it."
    )


#: The goals' keys in `bench.json` files written before the goals had names: old -> new.
OLD_KEYS = {
    "P1": "time_ratio_1e9",
    "P2": "time_ratio_1e6",
    "P3": "throughput",
    "P4": "gradient_ratio",
    "P5": "compile_time",
    "P7": "user_vmap_ratio",
    "P8": "user_grad_ratio",
    "P9": "cli_second_run",
    "P10": "default_user_ratio",
}


def upgrade(result: dict) -> dict:
    """A `bench.json` dictionary with its goals under today's keys: a shallow copy whose
    `goals` has every old key (P1–P5, P7–P10, see `OLD_KEYS`) renamed, in the same order;
    a dictionary with today's keys comes back equal."""
    goals = result.get("goals")
    if not isinstance(goals, dict):
        return dict(result)
    return {**result, "goals": {OLD_KEYS.get(key, key): goal for key, goal in goals.items()}}


def load(path) -> dict:
    """A `bench.json` file (str or path-like), old goal keys renamed (`upgrade`)."""
    import json

    with open(path, encoding="utf-8") as fh:
        return upgrade(json.load(fh))


#: The width of the goal table's first column: the longest key.
_KEY_WIDTH = max(len(key) for key in GOALS)


def goal_table(result: dict) -> str:
    """The printed table of the goals: value, target, met (a `bench.json` dictionary, old
    goal keys accepted)."""
    w = _KEY_WIDTH
    lines = [f"{'goal':<{w}} {'measured':>12} {'target':>10}  met  unit"]
    for key, goal in upgrade(result)["goals"].items():
        value = "n/a" if goal["value"] is None else f"{goal['value']:.4g}"
        cmp = "<=" if key != "throughput" else ">="
        met = "yes" if goal["met"] else "no "
        lines.append(f"{key:<{w}} {value:>12} {cmp}{goal['target']:>8.4g}  {met:<4} {goal['unit']}")
        lines += [
            f"{'':<{w}} {shown:>12} {limit:>10}  {'':<4} {what}"
            for shown, limit, what in _sub_rows(key, goal)
        ]
        if goal.get("note"):
            lines.append(f"{'':<{w}} note: {goal['note']}")
    return "\n".join(lines)


def _sub_rows(key: str, goal: dict) -> list[tuple[str, str, str]]:
    """The goal table's extra rows under a goal: (value, target, what)."""
    rows = []
    if key == "throughput" and goal.get("ratio_vs_scipy_loop") is not None:
        rows.append(
            (
                f"{goal['ratio_vs_scipy_loop']:.4g}",
                f">={goal['ratio_target']:>8.4g}",
                "ratio against the scipy loop",
            )
        )
    if key == "gradient_ratio" and goal.get("by_mode"):
        for mode, ratio in goal["by_mode"].items():
            how = "jax.grad" if mode == "reverse" else 'jax.jacfwd, autodiff="forward"'
            rows.append((f"{ratio:.4g}", "", f"{mode} mode ({how})"))
    if key == "user_grad_ratio" and goal.get("forward_mode_ratio") is not None:
        rows.append(
            (f"{goal['forward_mode_ratio']:.4g}", "", 'forward mode (jax.jacfwd, autodiff="forward")')
        )
    if key == "cli_second_run":
        for name, ratio in goal.get("by_command", {}).items():
            if name != "simulate":
                shown = f"{ratio:.4g}" if isinstance(ratio, float) else "n/a"
                why = "" if isinstance(ratio, float) else f" ({ratio})"
                rows.append((shown, "", f"jaxunilat {name}, second / first{why}"))
    return rows
