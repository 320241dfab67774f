"""The benchmark's goals measured the way users write code.

One scene for all four: Table 1 example 2 from the lower racket, event mode at
rtol = atol = 1e-10, 201 save times over [0, 1] s, every other option at its default
(`simulate`'s outputs, buffers and `throw`), written as a user would (`USER_CODE`):

- `user_vmap_ratio` (`vmap_against_rows`): `jax.jit(jax.vmap(f))` over N values of κ (±20 % about
  Table 1's) against `jaxunilat.sweep(f, kappas, batch_size=1)`, the rows one by one,
  unbatched, both on the same single device; the ratio of their warm medians. On a CPU
  `simulate`'s batching rule runs the vmapped rows one by one too (`lax.map`, see
  `_batching`; `batching` in the result says which rule ran), so the ratio is about 1;
  with `JAXUNILAT_VMAP=batch` (the GPU rule) the rows run in lockstep, about 2x slower.
- `vmap_outputs_ratio` (`vmap_outputs`): not the users' scene but the throughput scene
  (Table 1 example 2, Dopri8 pieces at 1e-10, [0, 2] s) under `jax.jit(jax.vmap(f))` in
  lockstep (`JAXUNILAT_VMAP=batch`, the GPU's rule, on any backend), N rows with 2001 save
  times against 2: what the outputs cost under `vmap`; the throughputs' ratio.
- `user_grad_ratio` (`reverse_against_forward`): `jax.jit(jax.grad(loss))` of a misfit (mean square of
  the trace against data plus mean square of the impact times against the data's) in
  (κ, k_r), against `jax.jit(loss)`, one forward solve of the same run; warm medians.
  Forward mode (`autodiff="forward"` with `jax.jacfwd`) beside it.
- `cli_second_run` (`command_line`): wall time of `jaxunilat simulate ball --solver event` run twice,
  each in a fresh process (`sys.executable -m jaxunilat`) sharing a new, empty cache
  directory (`JAXUNILAT_CACHE_DIR`: the compilation cache and `simulate`'s executables);
  the second against the first.
  `identify` (the bundled data) and `reproduce --quick` likewise, where the size has them.
- `default_user_ratio` (`default_user`): the default configuration against the tuned one, each in a fresh
  process (`DEFAULT_USER_CODE`): a plain script that never calls `use_loop_kernels`
  (what `import jaxunilat` sets up is all it gets) against the same script with the
  explicit call first; one `jax.jit(f)` solve and `jax.jit(jax.vmap(f))` over
  `DEFAULT_USER_N` rows, warm medians, the worse of the two ratios default / tuned.
"""

from __future__ import annotations

import contextlib
import json
import os
import shutil
import subprocess
import sys
import tempfile
import time

import numpy as np

#: The users' scene: Table 1 example 2 over [0, 1] s, 201 save times, event mode at 1e-10.
USER_T1 = 1.0
USER_SAMPLES = 201
USER_TOL = 1e-10
#: κ of user_vmap_ratio's rows: Table 1 example 2's, ±20 %.
KAPPA_SPREAD = 0.2
#: user_grad_ratio's parameters against those that made its data: κ 10 % higher, k_r 10 % lower.
MISFIT = (1.1, 0.9)

#: What user_vmap_ratio and user_grad_ratio time, as a user writes it (`bench.json` carries it as the goals' `reproduce`).
USER_CODE = """\
import jax, jax.numpy as jnp, numpy as np
import jaxunilat as ju
ju.use_loop_kernels()
y0 = (-0.4, -1 / 0.122)
def run(kappa, k_r=0.2, autodiff="reverse"):
    return ju.simulate(ju.Ball.table1(2, kappa=kappa, k_r=k_r), y0, 1.0, solver="event",
                       rtol=1e-10, atol=1e-10, samples=201, autodiff=autodiff)
def f(kappa):
    return run(kappa).ys["x"]
# user_vmap_ratio: N rows, vmapped against one by one (same device)
kappas = 1e4 * np.linspace(0.8, 1.2, N)
vmapped = jax.jit(jax.vmap(f)); vmapped(kappas)
ju.sweep(f, kappas, batch_size=1, devices=jax.devices()[:1])
# user_grad_ratio: a misfit against data made at (1e4, 0.2), at theta = (1.1e4, 0.18)
data = run(1e4); x_obs = data.ys["x"]
n = int(np.sum(np.isfinite(ju.impact_times(data, 64))))  # the data's impacts
t_obs = ju.impact_times(data, n)
def loss(theta, autodiff="reverse"):
    sol = run(theta[0], theta[1], autodiff)
    return jnp.mean((sol.ys["x"] - x_obs) ** 2) + jnp.mean((ju.impact_times(sol, n) - t_obs) ** 2)
theta = jnp.array([1.1e4, 0.18])
jax.jit(loss)(theta); jax.jit(jax.grad(loss))(theta)
jax.jit(jax.jacfwd(lambda th: loss(th, "forward")))(theta)
"""


#: default_user_ratio's script, run as `python -c` in a fresh process: `{setup}` is empty for the
#: default user, `ju.use_loop_kernels()` for the tuned one; `{n}` rows, `{repeats}` runs.
DEFAULT_USER_CODE = """\
import json, statistics, time, warnings
warnings.simplefilter("always")
with warnings.catch_warnings(record=True) as caught:
    import jax, numpy as np
    import jaxunilat as ju
    {setup}
    y0 = (-0.4, -1 / 0.122)
    def f(kappa):
        return ju.simulate(ju.Ball.table1(2, kappa=kappa), y0, 1.0, solver="event",
                           rtol=1e-10, atol=1e-10, samples=201).ys["x"]
    one, many = jax.jit(f), jax.jit(jax.vmap(f))
    kappas = jax.device_put(1e4 * np.linspace(0.8, 1.2, {n}))
    kappa = jax.device_put(1e4)
    def timed(fn, calls):
        start = time.perf_counter()
        for _ in range(calls):
            jax.block_until_ready(fn())
        return (time.perf_counter() - start) / calls
    timed(lambda: one(kappa), 1); timed(lambda: many(kappas), 1)  # compile
    calls = max(1, int(0.02 / timed(lambda: one(kappa), 3)))
    one_s = statistics.median(timed(lambda: one(kappa), calls) for _ in range({repeats}))
    vmap_s = statistics.median(timed(lambda: many(kappas), 1) for _ in range({repeats}))
print(json.dumps(dict(one_s=one_s, vmap_s=vmap_s, loop_kernel_bytes=ju.debug.loop_kernel_bytes(),
                      warnings=[str(w.message) for w in caught])))
"""
#: default_user_ratio's rows (the size's `user_n` where that is below 100: the test suite's tiny size).
DEFAULT_USER_N = 400


def _run(kappa, k_r=None, autodiff="reverse"):
    """The users' scene at (κ, k_r) (k_r default: Table 1 example 2's)."""
    from .._models._ball import Ball
    from .._solver._simulate import simulate
    from ._scale import Y0

    overrides = {"kappa": kappa} if k_r is None else {"kappa": kappa, "k_r": k_r}
    return simulate(
        Ball.table1(2, **overrides),
        np.asarray(Y0),
        USER_T1,
        solver="event",
        rtol=USER_TOL,
        atol=USER_TOL,
        samples=USER_SAMPLES,
        autodiff=autodiff,
    )


def _timed(fns, size, timed_together):
    """(compile times, timings) of calls compared with each other: `timed_together` with
    two warm-up rounds, the first with compilation, so that the number of runs follows the
    warm call's time (not the compile's)."""
    timings = timed_together(fns, size, warm_ups=2)
    return [max(t.first - t.median, 0.0) for t in timings], timings


def user_row(kappa):
    """user_vmap_ratio's f: one row, the saved positions (m). A module-level function: `sweep`
    caches its compiled program per function object."""
    return _run(kappa).ys["x"]


def kappa_rows(n: int) -> np.ndarray:
    """user_vmap_ratio's rows: n values of κ evenly over Table 1 example 2's ±20 % (N/m)."""
    from .._models._ball import TABLE1

    kappa = TABLE1[2][0]
    return kappa * np.linspace(1.0 - KAPPA_SPREAD, 1.0 + KAPPA_SPREAD, n)


# -- user_vmap_ratio -----------------------------------------------------------------------------------


def vmap_against_rows(size, timed_together, log) -> dict:
    """user_vmap_ratio: `jax.jit(jax.vmap(f))` against `sweep(f, ..., batch_size=1)` on one device."""
    import jax

    from .._solver._batching import batching_mode
    from .._solver._sweep import sweep

    n = size.user_n
    kappas = kappa_rows(n)
    device = jax.devices()[0]
    vmapped = jax.jit(jax.vmap(user_row))
    kappas_on_device = jax.device_put(kappas, device)
    compile_s, (vm, seq) = _timed(
        [
            lambda: jax.block_until_ready(vmapped(kappas_on_device)),
            lambda: jax.block_until_ready(sweep(user_row, kappas, batch_size=1, devices=[device])),
        ],
        size,
        timed_together,
    )
    x_vm, x_seq = np.asarray(vm.out), np.asarray(seq.out)
    out = {
        "scene": _scene(),
        "n": n,
        "kappa_range": [float(kappas[0]), float(kappas[-1])],
        "device": str(device),
        # simulate's rule under vmap: "rows" (lax.map, CPU) or "batch" (lockstep).
        "batching": batching_mode(),
        "vmap": "jax.jit(jax.vmap(f))(kappas)",
        "sequential": "jaxunilat.sweep(f, kappas, batch_size=1, devices=[device])",
        "vmap_s": vm.median,
        "sequential_s": seq.median,
        "vmap_per_row_s": vm.median / n,
        "sequential_per_row_s": seq.median / n,
        "ratio": vm.median / seq.median,
        "ratio_of_fastest_runs": vm.min / seq.min,
        "vmap_compile_s": compile_s[0],
        "sequential_compile_s": compile_s[1],
        "runs": vm.runs,
        # Both ways compute the same rows (rounding level apart).
        "max_abs_difference_m": float(np.max(np.abs(x_vm - x_seq))) if x_vm.shape == x_seq.shape else None,
    }
    log(
        f"  user_vmap_ratio N = {n}: jit(vmap(f)) {1e6 * out['vmap_per_row_s']:.1f} us/row, sweep(batch_size=1) "
        f"{1e6 * out['sequential_per_row_s']:.1f} us/row on {out['device']} ({out['batching']} rule): "
        f"ratio {out['ratio']:.2f} "
        f"(compile {out['vmap_compile_s']:.1f} s / {out['sequential_compile_s']:.1f} s)"
    )
    return out


# -- vmap_outputs_ratio ---------------------------------------------------------------------------------

#: vmap_outputs_ratio's save-time counts: the throughput scene's (2001) against two.
OUTPUT_SAMPLES = (2, 2001)


def vmap_outputs(size, timed_together, log) -> dict:
    """vmap_outputs_ratio: the throughput scene (Table 1 example 2, Dopri8 pieces at 1e-10,
    [0, 2] s) under `jax.jit(jax.vmap(f))` in lockstep (`JAXUNILAT_VMAP=batch`, the GPU's
    rule) with 2001 save times against 2: what the outputs cost under `vmap`, on this
    backend. The goal is a ratio of throughputs ≥ 0.7."""
    import jax

    from .._solver._batching import ENV
    from ._scale import pairs

    n = size.user_n
    kappa, k_r = (jax.device_put(v) for v in pairs(n))
    calls = []
    for samples in OUTPUT_SAMPLES:
        fn = _lockstep(samples)
        with _environment(ENV, "batch"):
            jax.block_until_ready(fn(kappa, k_r))  # traced and compiled under the lockstep rule
        calls.append(lambda fn=fn: jax.block_until_ready(fn(kappa, k_r)))
    compile_s, timings = _timed(calls, size, timed_together)
    few, many = timings
    status = max(int(np.max(np.asarray(t.out[1]))) for t in timings)
    out = {
        "scene": "Table 1 example 2, event mode, dopri8 pieces, rtol = atol = 1e-10, [0, 2] s, x saved",
        "n": n,
        "rule": "jax.jit(jax.vmap(f)) with JAXUNILAT_VMAP=batch (lockstep)",
        "samples": list(OUTPUT_SAMPLES),
        "throughput_traj_per_s": [n / few.median, n / many.median],
        "ratio": few.median / many.median,
        "time_ratio": many.median / few.median,
        "compile_s": compile_s,
        "runs": many.runs,
        "worst_status": status,
    }
    log(
        f"  vmap_outputs_ratio N = {n}: {out['throughput_traj_per_s'][0]:.0f} traj/s at 2 save times, "
        f"{out['throughput_traj_per_s'][1]:.0f} at 2001: ratio {out['ratio']:.2f} (lockstep vmap)"
    )
    return out


@contextlib.contextmanager
def _environment(name: str, value: str):
    """The environment variable `name` set to `value` inside the block, restored after."""
    previous = os.environ.get(name)
    os.environ[name] = value
    try:
        yield
    finally:
        if previous is None:
            os.environ.pop(name, None)
        else:
            os.environ[name] = previous


def _lockstep(samples: int):
    """`jax.jit(jax.vmap(row))` of the throughput scene's rows with `samples` save times
    (traced at its first call: call it with `JAXUNILAT_VMAP=batch` set)."""
    import jax

    from ._scale import solve

    def row(kappa, k_r):
        sol = solve(kappa, k_r, samples)
        return sol.ys["x"], sol.status

    return jax.jit(jax.vmap(row))


# -- user_grad_ratio -----------------------------------------------------------------------------------


def _misfit_data():
    """The data of user_grad_ratio's misfit: the trace and the impact times at Table 1 example 2's (κ, k_r)."""
    import jax

    from .._models._ball import TABLE1
    from .._solver._observe import impact_times

    kappa, k_r = TABLE1[2]
    data = jax.block_until_ready(_run(kappa, k_r))
    fitted = jax.block_until_ready(_run(MISFIT[0] * kappa, MISFIT[1] * k_r))
    # Impacts in both runs (the data's and the starting point's), so the misfit is finite.
    n = int(min(np.sum(np.isfinite(np.asarray(impact_times(s, 64)))) for s in (data, fitted)))
    return data.ys["x"], impact_times(data, n), n


def reverse_against_forward(size, timed_together, log) -> dict:
    """user_grad_ratio: `jax.jit(jax.grad(loss))` against `jax.jit(loss)` (and `jax.jacfwd` in
    forward mode); skipped where `size.user_grad` is off (its reverse-mode compile is slow)."""
    if not size.user_grad:
        return {"status": f"skipped at size {size.name}", "ratio": None}
    import jax
    import jax.numpy as jnp

    from .._models._ball import TABLE1
    from .._solver._observe import impact_times

    x_obs, t_obs, n = _misfit_data()

    def loss(theta, autodiff="reverse"):
        sol = _run(theta[0], theta[1], autodiff)
        return jnp.mean((sol.ys["x"] - x_obs) ** 2) + jnp.mean((impact_times(sol, n) - t_obs) ** 2)

    theta = jnp.array([MISFIT[0] * TABLE1[2][0], MISFIT[1] * TABLE1[2][1]])
    forward = jax.jit(loss)
    reverse = jax.jit(jax.grad(loss))
    forward_mode = jax.jit(jax.jacfwd(lambda th: loss(th, "forward")))
    compile_s, (fw, rev, fwd_mode) = _timed(
        [
            lambda: jax.block_until_ready(forward(theta)),
            lambda: jax.block_until_ready(reverse(theta)),
            lambda: jax.block_until_ready(forward_mode(theta)),
        ],
        size,
        timed_together,
    )
    g_rev, g_fwd = np.asarray(rev.out), np.asarray(fwd_mode.out)
    out = {
        "scene": _scene(),
        "loss": f"mean((x - x_obs)^2) [m^2] + mean((t_imp - t_obs)^2) [s^2] over the first {n} impacts; "
        f"data at Table 1 example 2's (kappa, k_r), theta = ({MISFIT[0]:g} kappa, {MISFIT[1]:g} k_r)",
        "impacts": n,
        "theta": [float(v) for v in np.asarray(theta)],
        "loss_value": float(fw.out),
        "forward": "jax.jit(loss)(theta)",
        "reverse": "jax.jit(jax.grad(loss))(theta)",
        "forward_mode": 'jax.jit(jax.jacfwd(loss with autodiff="forward"))(theta)',
        "forward_s": fw.median,
        "reverse_s": rev.median,
        "forward_mode_s": fwd_mode.median,
        "ratio": rev.median / fw.median,
        "ratio_of_fastest_runs": rev.min / fw.min,
        "forward_mode_ratio": fwd_mode.median / fw.median,
        "forward_compile_s": compile_s[0],
        "reverse_compile_s": compile_s[1],
        "forward_mode_compile_s": compile_s[2],
        "runs": fw.runs,
        "gradient": [float(v) for v in g_rev],
        "gradient_forward_mode": [float(v) for v in g_fwd],
        # The two modes' gradients agree (a check that both measured the same thing).
        "modes_max_rel_difference": float(np.max(np.abs(g_rev - g_fwd) / np.abs(g_fwd))),
    }
    log(
        f"  user_grad_ratio: jax.grad(loss) {out['ratio']:.1f}x jax.jit(loss) (forward {1e3 * out['forward_s']:.2f} ms, "
        f"reverse {1e3 * out['reverse_s']:.2f} ms, compile {out['reverse_compile_s']:.1f} s); forward mode "
        f"(jax.jacfwd) {out['forward_mode_ratio']:.1f}x; modes agree to {out['modes_max_rel_difference']:.1e}"
    )
    return out


def _scene() -> str:
    return (
        f"Table 1 example 2, y0 = (-0.4 m, -1/0.122 m/s), [0, {USER_T1:g}] s, {USER_SAMPLES} save times, "
        f"event mode rtol = atol = {USER_TOL:g}, other options at their defaults"
    )


# -- cli_second_run -----------------------------------------------------------------------------------

#: cli_second_run's commands: name -> the arguments after `jaxunilat` (`{out}`: a folder in the run's
#: working directory, a temporary one; `{data}`: the bundled drop trace).
CLI_COMMANDS = {
    "simulate": ("simulate", "ball", "--solver", "event"),
    "identify": ("identify", "{data}"),
    "reproduce": ("reproduce", "--quick", "--out", "{out}"),
}


def _child_env(cache: str) -> dict:
    """The user's environment for a child `jaxunilat`: this one, with the cache in `cache`
    and on, without the CPU device count this process gave itself (`host_devices`), and
    with this copy of the package first on the path."""
    from . import _scale as _bench_scale

    env = dict(os.environ)
    env.pop("JAXUNILAT_NO_CACHE", None)
    env["JAXUNILAT_CACHE_DIR"] = cache
    flags = env.get("XLA_FLAGS", "")
    if _bench_scale.ADDED_XLA_FLAG:
        flags = " ".join(flags.replace(_bench_scale.ADDED_XLA_FLAG, " ").split())
    if flags:
        env["XLA_FLAGS"] = flags
    else:
        env.pop("XLA_FLAGS", None)
    # The folder that holds this copy of the package (jaxunilat/_bench/ is two levels down).
    root = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
    env["PYTHONPATH"] = os.pathsep.join(p for p in (root, env.get("PYTHONPATH", "")) if p)
    return env


def _user_process(setup: str, n: int, repeats: int) -> dict:
    """default_user_ratio's script (`DEFAULT_USER_CODE`) in a fresh process with the user's environment:
    `XLA_FLAGS` without the loop-kernel option this process has (the child's import adds
    it again, or its `setup` does), and no opt-out."""
    from .._internal._loop_kernels import OPT_OUT, without_option

    env = _child_env(tempfile.gettempdir())
    env.pop(OPT_OUT, None)
    flags = without_option(env.get("XLA_FLAGS", ""))
    if flags:
        env["XLA_FLAGS"] = flags
    else:
        env.pop("XLA_FLAGS", None)
    code = DEFAULT_USER_CODE.format(setup=setup or "pass", n=n, repeats=repeats)
    proc = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, check=False)
    if proc.returncode != 0:
        return {"error": (proc.stderr.strip().splitlines() or ["no output"])[-1]}
    return json.loads(proc.stdout.strip().splitlines()[-1])


def default_user(size, log) -> dict:
    """default_user_ratio: the users' plain script (no `use_loop_kernels` call) against the
    tuned one (the explicit call first), each in a fresh process; default / tuned, the worse
    of a single `jax.jit(f)` solve and `jax.jit(jax.vmap(f))` over the rows. Skipped where
    `size.default_user` is off."""
    if not size.default_user:
        return {"status": f"skipped at size {size.name}", "ratio": None}
    n = DEFAULT_USER_N if size.user_n >= 100 else size.user_n  # the test suite's tiny size: few rows
    repeats = max(size.repeats, 3)
    default = _user_process("", n, repeats)
    tuned = _user_process("ju.use_loop_kernels()", n, repeats)
    out = {
        "scene": _scene(),
        "n": n,
        "how": "each script a fresh process (python -c), the environment without the loop-kernel option; "
        "warm medians of one jax.jit(f) solve and of jax.jit(jax.vmap(f)) over n values of kappa",
        "default_code": DEFAULT_USER_CODE.format(setup="pass", n=n, repeats=repeats),
        "tuned_setup": "ju.use_loop_kernels()",
        "default": default,
        "tuned": tuned,
        "ratio": None,
    }
    if "error" in default or "error" in tuned:
        log(f"  default_user_ratio failed: {default.get('error') or tuned.get('error')}")
        return out
    out["one_ratio"] = default["one_s"] / tuned["one_s"]
    out["vmap_ratio"] = default["vmap_s"] / tuned["vmap_s"]
    out["ratio"] = max(out["one_ratio"], out["vmap_ratio"])
    log(
        f"  default_user_ratio: default user: one solve {1e3 * default['one_s']:.3f} ms (tuned {1e3 * tuned['one_s']:.3f} ms), "
        f"jit(vmap(f)) {n / default['vmap_s']:.0f} traj/s (tuned {n / tuned['vmap_s']:.0f}): "
        f"ratio {out['ratio']:.2f}"
    )
    return out


def _bundled_trace() -> str:
    """The bundled drop trace for cli_second_run's `identify` (the child runs in a temporary folder)."""
    from .._internal._io import bundled_data

    found = bundled_data("drop_trace.csv")
    return found[0] if found else "data/drop_trace.csv"


def _cache_files(path: str) -> tuple[int, int]:
    """(files, bytes) in the cache directory, its `executables` folder included."""
    names = [os.path.join(folder, f) for folder, _, files in os.walk(path) for f in files]
    return len(names), sum(os.path.getsize(f) for f in names)


def _cli_pair(name: str, log) -> dict:
    """Run one command twice, each in a fresh process, on one new cache directory."""
    work = tempfile.mkdtemp(prefix=f"jaxunilat-bench-{name}-")
    cache = os.path.join(work, "cache")
    try:
        env = _child_env(cache)
        runs = []
        for i in (1, 2):
            args = [
                a.format(out=os.path.join(work, f"out{i}"), data=_bundled_trace()) for a in CLI_COMMANDS[name]
            ]
            start = time.perf_counter()
            proc = subprocess.run(
                [sys.executable, "-m", "jaxunilat", *args],
                env=env,
                cwd=work,
                capture_output=True,
                text=True,
                check=False,
            )
            wall = time.perf_counter() - start
            files, size = _cache_files(cache)
            runs.append(
                {"wall_s": wall, "returncode": proc.returncode, "cache_files": files, "cache_bytes": size}
            )
            if proc.returncode != 0:
                tail = (proc.stderr.strip().splitlines() or ["no output"])[-1]
                runs[-1]["error"] = tail
                break
    finally:
        shutil.rmtree(work, ignore_errors=True)
    ok = len(runs) == 2 and all(r["returncode"] == 0 for r in runs)
    row = {
        "command": "jaxunilat " + " ".join(a.replace("{out}", "DIR") for a in CLI_COMMANDS[name]),
        "first_s": runs[0]["wall_s"],
        "second_s": runs[1]["wall_s"] if len(runs) == 2 else None,
        "ratio": runs[1]["wall_s"] / runs[0]["wall_s"] if ok else None,
        "ok": ok,
        "runs": runs,
    }
    if ok:
        log(
            f"  cli_second_run {row['command']}: first {row['first_s']:.2f} s, second {row['second_s']:.2f} s "
            f"(ratio {row['ratio']:.2f}; cache {runs[0]['cache_files']} files, {runs[0]['cache_bytes'] / 1e6:.1f} MB)"
        )
    else:
        log(f"  cli_second_run {row['command']}: failed: {runs[-1].get('error')}")
    return row


def _import_s() -> float | None:
    """Wall time of a fresh process that only imports jaxunilat: the floor of any command."""
    start = time.perf_counter()
    proc = subprocess.run(
        [sys.executable, "-c", "import jaxunilat"], env=_child_env(tempfile.gettempdir()), capture_output=True
    )
    return time.perf_counter() - start if proc.returncode == 0 else None


def command_line(size, log) -> dict:
    """cli_second_run: each command of `size.user_cli` twice in fresh processes on a new compilation cache."""
    out = {
        "how": "each command twice, each a fresh process (sys.executable -m jaxunilat) with "
        "JAXUNILAT_CACHE_DIR a new empty directory for the pair and this process's environment "
        "otherwise (less the CPU device count the bench gave itself); wall time of the process",
        "import_s": _import_s() if set(size.user_cli) & set(CLI_COMMANDS) else None,
        "commands": {},
    }
    if out["import_s"] is not None:
        log(f"  cli_second_run: a fresh process that imports jaxunilat: {out['import_s']:.2f} s")
    for name in CLI_COMMANDS:
        if name in size.user_cli:
            out["commands"][name] = _cli_pair(name, log)
        else:
            why = "slow for this size" if name == "reproduce" else "left out at this size"
            out["commands"][name] = {"status": f"skipped at size {size.name} ({why})"}
    return out
