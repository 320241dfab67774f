"""The benchmark's goals P1–P5: values from the measured sections, notes on missed ones.

The goals (SPEC §4, issue 8): P1, P2 ratios against the best peer in the same run; P3
trajectories per second (and the ratio against a scipy loop); P4 gradient / forward;
P5 compile time. Where a goal is missed, `notes` says why and what would close it,
from the run's own figures.
"""

from __future__ import annotations

GOALS = {
    "P1": dict(target=1 / 20, unit="time ratio (project / best peer) at error <= 1e-9 m"),
    "P2": dict(target=1 / 50, unit="time ratio (project / best peer) at error <= 1e-6 m"),
    "P3": dict(target=1e4, unit="trajectories/s at the largest N, error <= 1e-8 m", ratio_target=300.0),
    "P4": dict(
        target=5.0,
        unit="gradient time / forward time (worst of the two losses, in the cheaper AD mode for (kappa, k_r))",
    ),
    "P5": dict(target=3.0, unit="s, compile time of the event-mode forward scene"),
}
P1_ERROR, P2_ERROR, P3_ERROR = 1e-9, 1e-6, 1e-8
#: A step buffer that holds example 2 over [0, 2] s down to tol 1e-12 (1591 steps).
SMALL_BUFFER = 1024


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


def goals(result: dict) -> dict:
    """P1–P5 from the measured sections, each with value, target, met, unit and a note."""
    wp = result["work_precision"]
    out = {"P1": _ratio_goal("P1", wp, P1_ERROR), "P2": _ratio_goal("P2", wp, P2_ERROR)}
    tp = [r for r in result["throughput"] if not r["peer"]]
    loop = [r for r in result["throughput"] if r["peer"]]
    big = max(tp, key=lambda r: r["n"])
    ratio = big["traj_per_s"] / loop[0]["traj_per_s"] if loop else None
    accurate = result["throughput_checks"]["max_error_m"] <= P3_ERROR
    out["P3"] = {
        "target": GOALS["P3"]["target"],
        "unit": GOALS["P3"]["unit"],
        "value": big["traj_per_s"],
        "n": big["n"],
        "ratio_vs_scipy_loop": ratio,
        "ratio_target": GOALS["P3"]["ratio_target"],
        "max_error_m": result["throughput_checks"]["max_error_m"],
        "met": bool(
            accurate and big["traj_per_s"] >= GOALS["P3"]["target"] and ratio is not None and ratio >= 300
        ),
    }
    losses = result["gradient"]["losses"]
    # The worst loss in each mode (reverse: jax.grad; forward: jax.jacfwd with
    # autodiff="forward"); P4 is the cheaper mode, the way to take a gradient in few parameters.
    by_mode = {}
    for row in losses:
        mode = row.get("mode", "reverse")
        by_mode[mode] = max(by_mode.get(mode, 0.0), row["ratio"])
    best = min(by_mode, key=by_mode.get) if by_mode else None
    out["P4"] = {
        "target": GOALS["P4"]["target"],
        "unit": GOALS["P4"]["unit"],
        "value": None if best is None else by_mode[best],
        "mode": best,
        "by_mode": by_mode,
        "met": best is not None and by_mode[best] <= GOALS["P4"]["target"],
    }
    compile_s = result["compile_s"].get("event tsit5")
    out["P5"] = {
        "target": GOALS["P5"]["target"],
        "unit": GOALS["P5"]["unit"],
        "value": compile_s,
        "met": compile_s is not None and compile_s <= GOALS["P5"]["target"],
        "gradient_compile_s": max((r["gradient_compile_s"] for r in losses), default=None),
        "gradient_compile_s_by_mode": {
            mode: max(r["gradient_compile_s"] for r in losses if r.get("mode", "reverse") == mode)
            for mode in by_mode
        },
    }
    for key, note in notes(result, out).items():
        out[key]["note"] = note
    return out


def notes(result: dict, out: dict) -> dict:
    """Why a goal is missed and what would close it, from this run's own figures."""
    fit = result["profile"].get("per_step_fit")
    notes = {}
    if fit:
        step_us, fixed_ms = 1e6 * fit["per_step_s"], 1e3 * result["profile"]["fixed_call_s"]
        cost = (
            f"the event mode costs about {fixed_ms:.2f} ms per call (measured over a 1 us span) plus "
            f"{step_us:.1f} us per step (fit over its tolerances), against 75 ns per step for RK4 in C (SPEC §4)"
        )
    else:
        cost = "the event mode's per-step cost dominates"
    wp = result["work_precision"]
    buffer = ""
    for tol in ("1e-08", "1e-10"):
        big = [r for r in wp if r["method"] == "event (dopri8)" and r["setting"] == f"tol {tol}"]
        small = [
            r
            for r in wp
            if r["method"].startswith("event (dopri8), max_steps") and r["setting"] == f"tol {tol}"
        ]
        if big and small:
            buffer += (
                f" At tol {tol} the default step buffer (max_steps 16384) takes {1e3 * big[0]['wall_s']:.2f} ms, "
                f"a {SMALL_BUFFER}-step buffer {1e3 * small[0]['wall_s']:.2f} ms."
            )
    if buffer:
        buffer += " (The event mode initialises and searches O(max_steps) buffers on every call.)"
    for key in ("P1", "P2"):
        if not out[key]["met"]:
            notes[key] = (
                f"missed: {cost}.{buffer} What would close it: a step buffer sized from the span and "
                "tolerance (or grown on demand), and, since the flight is in closed form and only the "
                "~1.5 ms contacts take steps, a leaner per-step body for them (fewer sub-grid crossing "
                "checks, no per-step buffer writes) or a custom CPU kernel per step."
            )
    if not out["P3"]["met"]:
        tp = max((r for r in result["throughput"] if not r["peer"]), key=lambda r: r["n"])
        lock = tp["steps_max"] / tp["steps_mean"] if tp["steps_mean"] else float("nan")
        one = [r for r in result["throughput"] if not r["peer"] and r["n"] == 1]
        solo = [
            r
            for r in result["work_precision"]
            if r["method"] == "event (dopri8)" and r["setting"] == "tol 1e-10"
        ]
        batched = ""
        if one and solo:
            prof = result["profile"]
            branch = max((max(b) for b in prof.get("cond_branches", []) if b), default=0)
            batched = (
                f"a batch of one costs {1e3 * one[0]['wall_s']:.1f} ms against {1e3 * solo[0]['wall_s']:.1f} ms "
                "unbatched: under vmap the loop's lax.cond (event location only on steps with a crossing, "
                f"{branch} of the body's {prof.get('loop_body_equations', '?')} equations) becomes a select, "
                "so every row runs the root finders on every step; "
            )
        notes["P3"] = (
            f"missed: {batched}vmap lockstep runs every row for the slowest row's {tp['steps_max']} steps "
            f"(mean {tp['steps_mean']:.0f}, factor {lock:.2f}), each vmapped step also writes "
            f"per-row buffers (scatter); {cost}. What would close it: "
            "sorting rows by expected step count into buckets, more devices (the sweep shards the "
            "batch: see scale_out)."
        )
    if not out["P4"]["met"] and out["P4"]["value"] is not None:
        modes = ", ".join(f"{mode} {ratio:.1f}x" for mode, ratio in out["P4"]["by_mode"].items())
        notes["P4"] = (
            f"missed ({modes}): the event loop is an equinox checkpointed while loop with every step a checkpoint, "
            "so reverse mode stores each step's carry (O(max_steps) memory, 2048 here) and then runs the "
            "VJP of every step's full body (RK stages, dense interpolant, sub-grid checks, the root "
            "finders' Newton update) sequentially; the backward of the output evaluation runs one RK step per save "
            "time and scatters into the step record. What would close it: a smaller step body for the contact steps, "
            "or an adjoint per smooth segment (solve the adjoint ODE backwards with the jump conditions "
            "at the located events)."
        )
    if not out["P5"]["met"]:
        eq = [r["equations"] for r in result["static_structure"] if r["scene"] in ("drag on", "drag = 0")]
        size = f" ({eq[0]} equations)" if eq else ""
        notes["P5"] = (
            f"missed: the event-mode graph{size} unrolls the RK stages (in the loop, and again for the "
            "outputs at the save times), the dense interpolant, the sub-grid crossing checks and the Newton root finder; what would close it: a smaller "
            "graph (fewer sub-grid checks, one shared root finder), or the persistent compilation "
            "cache (jax.config.update('jax_compilation_cache_dir', ...)) across runs."
        )
    return notes


def goal_table(result: dict) -> str:
    """The printed table of P1–P5: value, target, met."""
    lines = [f"{'goal':<4} {'measured':>12} {'target':>10}  met  unit"]
    for key, goal in result["goals"].items():
        value = "n/a" if goal["value"] is None else f"{goal['value']:.4g}"
        cmp = "<=" if key != "P3" else ">="
        lines.append(
            f"{key:<4} {value:>12} {cmp}{goal['target']:>8.4g}  {'yes' if goal['met'] else 'no ':<4} {goal['unit']}"
        )
        if key == "P3" and goal.get("ratio_vs_scipy_loop") is not None:
            lines.append(
                f"{'':<4} {goal['ratio_vs_scipy_loop']:>12.4g} >={goal['ratio_target']:>8.4g}  "
                f"{'':<4} ratio against the scipy loop"
            )
        if key == "P4" and goal.get("by_mode"):
            for mode, ratio in goal["by_mode"].items():
                how = "jax.grad" if mode == "reverse" else 'jax.jacfwd, autodiff="forward"'
                lines.append(f"{'':<4} {ratio:>12.4g} {'':>10}  {'':<4} {mode} mode ({how})")
        if goal.get("note"):
            lines.append(f"     note: {goal['note']}")
    return "\n".join(lines)
