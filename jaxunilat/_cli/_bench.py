"""`jaxunilat bench [--quick] [--out DIR]`: the benchmark command (needs scipy: the `bench` extra)."""

from __future__ import annotations

import argparse
import os

#: The files `bench` writes into its --out folder.
OUTPUT_FILES = ("bench.json", "work_precision.png", "throughput.png")


def add_bench(commands) -> None:
    """Add the `bench` command to the top-level subparsers."""
    p = commands.add_parser(
        "bench",
        help="benchmark run time against error, throughput, gradient cost and compile time",
        description="Benchmark Table 1 example 2 [K90] against scipy and NumPy peers, and a compiled "
        "event-located DOP853 loop (Numba) where installed, in the same run; write bench.json, "
        "work_precision.png and throughput.png and print the goals (time ratios against the best peer at 1e-9 m and "
        "1e-6 m, throughput, gradient and compile cost, plain vmap, jax.grad, the command line's second "
        "run and a default user's script, as users write them). "
        "The full size also times sweeps over 1, 2 and 4 processes and a cold 30-throw joint fit. "
        'Needs scipy (and numba for the compiled loop): pip install "jaxunilat[bench]".',
    )
    p.add_argument("--quick", action="store_true", help="a reduced run (under 3 minutes)")
    p.add_argument("--out", metavar="DIR", default="bench_out", help="output folder (default bench_out)")
    # For the test suite only: the smallest settings that still run every section.
    p.add_argument("--size", choices=("full", "quick", "tiny"), default=None, help=argparse.SUPPRESS)
    p.set_defaults(func=_run_bench)


def _run_bench(args) -> int:
    from .._internal._cli import input_errors, output_errors
    from .._internal._errors import EXIT_OK, RunError, UsageError
    from .._internal._io import check_output_dir
    from .._internal._text import printable

    out = args.out
    with input_errors():
        check_output_dir("--out", out, OUTPUT_FILES)
    try:
        import scipy  # noqa: F401
    except ImportError:
        raise UsageError(
            'jaxunilat bench needs scipy; install it with: pip install "jaxunilat[bench]"'
        ) from None
    size = args.size or ("quick" if args.quick else "full")
    try:
        os.makedirs(out, exist_ok=True)
    except OSError as err:
        raise RunError(f"cannot create --out {out!r}: {err}") from None

    import json

    from .._bench._scale import host_devices

    # Before anything computes: one CPU device per core, so that sweeps use every core.
    host_devices()
    # The bench measures compile times (P5 and every compile_s): no persistent compilation
    # cache nor executable cache in this process (P9 measures the caches, in child
    # processes with a new one).
    import jax

    from .._internal._executables import disable_executable_cache

    jax.config.update("jax_enable_compilation_cache", False)
    disable_executable_cache()

    from .._bench._main import goal_table, run_bench
    from .._bench._plot import throughput_figure, work_precision_figure
    from .._internal import write_atomically
    from ..plot import save_figure

    result = run_bench(size, log=lambda line: print(line, flush=True))
    paths = {name: os.path.join(out, name) for name in OUTPUT_FILES}
    with output_errors("--out", paths["bench.json"]):
        with write_atomically(paths["bench.json"], encoding="utf-8") as fh:
            json.dump(result, fh, indent=1, allow_nan=False)
    for name, figure in (
        ("work_precision.png", work_precision_figure),
        ("throughput.png", throughput_figure),
    ):
        with output_errors("--out", paths[name]):
            save_figure(figure(result), paths[name])
    print()
    print(goal_table(result))
    print(f"\nwrote {', '.join(printable(p) for p in paths.values())} ({result['total_s']:.0f} s)")
    return EXIT_OK
