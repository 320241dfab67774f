"""`sweep`: a `jax.vmap` over a batch, sharded across all visible devices.

The batch axis is split over a one-axis device `Mesh` ("batch") with `NamedSharding`,
and `shard_map` runs each device's rows on that device. The same code
runs on one CPU, one GPU, several local devices (e.g. `XLA_FLAGS=
--xla_force_host_platform_device_count=2`, one CPU device per core) and, after
`jax.distributed.initialize()`, on the devices of several processes or hosts.

Several processes: every process calls `sweep` with the same function and the same
arguments. Before anything runs, the processes compare two fingerprints each (one
small all-gather): a CRC-32 of the arguments' shapes, dtypes and bytes, and a CRC-32 of
the program that `sweep` lowered from the function (its StableHLO text, which has no
source locations or addresses, so it is the same on every process that traces the same
function; the values the function closes over are constants in it; host callbacks
appear by position only). Either mismatch is an `InputError` on every process, and
nothing runs (a new program is not even compiled). The program's fingerprint is computed only when the mesh
spans several processes, once per compiled program (cached with it). Each process
places only its own devices' rows, from its own copy (`jax.make_array_from_callback`,
no inputs cross between processes); the padded batch is split into contiguous blocks
in the order of `devices` (process 0's devices first, by default), so each row is
computed by one device only (the padding rows repeat the last one). The result is
gathered to every process (`multihost_utils.process_allgather`, through the backend's
collectives: on CPUs set `jax_cpu_collectives_implementation` to "gloo" before
`jax.distributed.initialize`) and returned as NumPy arrays. With `devices` from one
process only (e.g. `jax.local_devices()`) each process sweeps on its own and nothing is
gathered or compared. `tests/distributed_worker.py` is a complete example; a process
that dies ends the others through `jax.distributed`'s heartbeat
(`heartbeat_timeout_seconds`).

Batch sizing (`batch_size=None`, `_sized`). Where `simulate` batches in lockstep (a GPU;
`batching_mode() == "batch"`) a vmapped solve holds every row's loop buffers at once, so the
rows one device may hold at once are sized from the compiled program's memory analysis and
the device's free memory: all of them if the whole batch's program (temp + output + argument
bytes) fits in `HEADROOM` of the free memory, else the per-row bytes of each kind are the
slope between that program and one for another number of rows (an earlier sweep's, else one
compiled for `_PROBE` rows), and the device's rows run in equal chunks (`lax.map`, a
multiple of `ALIGN` rows where possible) of the largest size whose temporaries, with every
row's arguments and outputs, fit (`chunk_rows`). A size chosen once is kept while it fits
(new values do not recompile). Free memory: `bytes_limit - bytes_in_use` of
`Device.memory_stats()`, or on a host device the host's available memory (at most
`HOST_CAP`, shared by this process's devices in the mesh); the processes of a multi-process
mesh take the smallest. Where `simulate` runs vmapped rows one by one (a CPU) a row's work
is not held for every row, and `sweep` vmaps all rows at once as before.
"""

from __future__ import annotations

import math
import os
import zlib
from collections.abc import Callable, Sequence
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np
from jax.sharding import Mesh, NamedSharding, PartitionSpec

from .._internal._errors import InputError
from ._batching import batching_mode
from ._simulate import _TRACES, one_failure_message

AXIS = "batch"

#: (fn, in_axes, device ids) -> (the jitted sharded vmapped function, batched and
#: replicated shardings); and (that key, argument types) -> (its compiled executable,
#: its program fingerprint or None on one process).
_CACHE: dict[tuple, tuple] = {}
_EXECUTABLES: dict[tuple, tuple] = {}

#: The share of a device's free memory that an automatically sized batch may fill.
HEADROOM = 0.6
#: The most host memory a batch on host (CPU) devices is sized for, bytes.
HOST_CAP = 64 * 2**30
#: A chunk is a multiple of this many rows where it can be (`chunk_rows`).
ALIGN = 8
#: Rows per device that `sweep` vmaps at once without measuring (fewer than twice the probe).
_SMALL = 64
#: Rows per device of the program compiled to measure the per-row bytes.
_PROBE = 32
#: The per-row bytes of a function's program, (temp, output, argument) and the fixed bytes,
#: by (fn, axes, device ids, the rows' types); and the batch chosen for a number of rows per
#: device, with the bytes it needs: reused while that still fits (no new compile).
_SIZING: dict[tuple, tuple] = {}
_CHOSEN: dict[tuple, tuple] = {}
#: The memory analyses of the whole-batch programs compiled so far, by that key and rows
#: per device (a second one gives the slope without a probe).
_POINTS: dict[tuple, dict] = {}


def _normalize_axes(in_axes, n_args: int) -> tuple[int | None, ...]:
    if isinstance(in_axes, (int, type(None))):
        axes = (in_axes,) * n_args
    else:
        axes = tuple(in_axes)
    if len(axes) != n_args:
        raise InputError(
            f"in_axes = {in_axes!r} has {len(axes)} entries; expected one per argument ({n_args})"
        )
    for axis in axes:
        if axis not in (0, None):
            raise InputError(f"in_axes entry {axis!r} is out of range; valid entries are 0 (batched) or None")
    return axes


def _program(fn: Callable, axes: tuple[int | None, ...], devices: tuple, batch_size: int | None):
    """(jitted sharded function, batched sharding, replicated sharding), cached per call signature.

    `shard_map` hands every device its own rows; each device runs `jax.vmap(fn)` over
    them, or `lax.map` over chunks of `batch_size` vmapped rows.
    """
    key = (fn, axes, tuple(d.id for d in devices), batch_size)
    if key not in _CACHE:
        mesh = Mesh(np.asarray(devices), (AXIS,))
        batched, replicated = NamedSharding(mesh, PartitionSpec(AXIS)), NamedSharding(mesh, PartitionSpec())

        def local(*args):
            if batch_size is None:
                return jax.vmap(fn, in_axes=axes)(*args)
            rows = tuple(a for a, axis in zip(args, axes, strict=True) if axis == 0)

            def one(row):
                it = iter(row)
                return fn(*(next(it) if axis == 0 else a for a, axis in zip(args, axes, strict=True)))

            # One row at a time: no vmap at all (a vmap of one row would still batch
            # the loops' predicates).
            return jax.lax.map(one, rows, batch_size=None if batch_size == 1 else batch_size)

        def body(*args):
            _TRACES["sweep"] += 1
            specs = tuple(PartitionSpec(AXIS) if a == 0 else PartitionSpec() for a in axes)
            # check_vma=False: the solvers stack per-row (device-varying) values with
            # constants, which the varying-axes checker rejects; every row is independent.
            return jax.shard_map(
                local, mesh=mesh, in_specs=specs, out_specs=PartitionSpec(AXIS), check_vma=False
            )(*args)

        jitted = jax.jit(
            body,
            in_shardings=tuple(batched if a == 0 else replicated for a in axes),
            out_shardings=batched,
        )
        _CACHE[key] = (jitted, batched, replicated)
    return _CACHE[key]


def _executable(fn, axes, devices, batch_size, placed, args):
    """The compiled program for these placed arguments (cached per shapes and dtypes,
    with its fingerprint), compiled only once the processes agree on it and on `args`
    (`_check_same`): a mismatch compiles nothing. The fingerprint (`_fingerprint`) is
    computed only when the processes compare it (`_compared`)."""
    jitted = _program(fn, axes, devices, batch_size)[0]
    leaves, treedef = jax.tree_util.tree_flatten(placed)
    key = (fn, axes, tuple(d.id for d in devices), batch_size, treedef)
    key += tuple(jax.typeof(leaf) for leaf in leaves)
    if key in _EXECUTABLES:
        compiled, program = _EXECUTABLES[key]
        _check_same(args, program)
        return compiled
    lowered = jitted.lower(*placed)
    program = _fingerprint(lowered) if _compared(devices) else None
    _check_same(args, program)
    _EXECUTABLES[key] = (lowered.compile(), program)
    return _EXECUTABLES[key][0]


def _fingerprint(lowered) -> int:
    """CRC-32 of a lowered program's StableHLO text. Without debug info the text holds no
    source locations, memory addresses or process index (host callbacks are numbered), so
    processes that trace the same function get the same number; a constant the function
    closes over (e.g. an end time) is part of the text."""
    return zlib.crc32(lowered.as_text(debug_info=False).encode())


def _batch_size(args, axes) -> int:
    sizes = {
        np.shape(leaf)[0] if np.ndim(leaf) else None
        for arg, axis in zip(args, axes, strict=True)
        if axis == 0
        for leaf in jax.tree_util.tree_leaves(arg)
    }
    if not sizes:
        raise InputError("in_axes marks no argument as batched (0); at least one must be")
    if None in sizes or len(sizes) != 1:
        raise InputError(f"the batched arguments' leading axes disagree or are missing: sizes {sizes}")
    (n,) = sizes
    if n < 1:
        raise InputError("the batch is empty; pass at least one row")
    return n


def _pad(leaf, n_pad: int, xp=jnp):
    """Repeat the last row n_pad times (the padded rows are valid inputs, then dropped);
    `xp`: the array module (jax.numpy, or NumPy for a host copy)."""
    if n_pad == 0:
        return leaf
    leaf = xp.asarray(leaf)
    return xp.concatenate([leaf, xp.repeat(leaf[-1:], n_pad, axis=0)], axis=0)


def _gather(out):
    """Bring every leaf that spans several processes to every process, as a NumPy array
    (each process gets all rows; single-process and process-local results are returned
    as they are)."""
    if jax.process_count() == 1:
        return out
    from jax.experimental import multihost_utils

    def one(leaf):
        if isinstance(leaf, jax.Array) and not leaf.is_fully_addressable:
            return multihost_utils.process_allgather(leaf, tiled=True)
        return leaf

    return jax.tree_util.tree_map(one, out)


def _place(leaf, sharding, n_pad: int | None):
    """`leaf` on `sharding`: a batched leaf (`n_pad` an int) padded with `n_pad` copies of
    its last row, a replicated one (`n_pad` None) as it is.

    A sharding that spans several processes gets each process's own shards from its
    host copy (`jax.make_array_from_callback`: no data crosses between processes;
    `_check_same` refuses, before anything runs, a batch that differs between them).
    Python scalars and arrays that already span processes go through `jax.device_put`.
    """
    host_array = isinstance(leaf, np.ndarray) or (isinstance(leaf, jax.Array) and leaf.is_fully_addressable)
    if sharding.is_fully_addressable or not host_array:
        return jax.device_put(jnp.asarray(leaf) if n_pad is None else _pad(leaf, n_pad), sharding)
    host = np.asarray(leaf) if n_pad is None else _pad(np.asarray(leaf), n_pad, np)
    return jax.make_array_from_callback(host.shape, sharding, lambda index: host[index])


def _place_all(args, axes, batched, replicated, n_pad: int) -> tuple:
    """Every argument on its sharding (the batched ones padded)."""
    return tuple(
        jax.tree_util.tree_map(lambda leaf: _place(leaf, batched, n_pad), arg)
        if axis == 0
        else jax.tree_util.tree_map(lambda leaf: _place(leaf, replicated, None), arg)
        for arg, axis in zip(args, axes, strict=True)
    )


def _compared(devices) -> bool:
    """Whether the processes compare fingerprints: the mesh spans several processes and
    every process takes part (each must join the all-gather)."""
    return len({d.process_index for d in devices}) >= max(2, jax.process_count())


def _args_fingerprint(args) -> int:
    """CRC-32 of the host arguments' shapes, dtypes and bytes (arrays that already span
    processes are skipped: nothing to compare)."""
    crc = 0
    for leaf in jax.tree_util.tree_leaves(args):
        if isinstance(leaf, jax.Array) and not leaf.is_fully_addressable:
            continue
        host = np.ascontiguousarray(leaf)
        crc = zlib.crc32(f"{host.shape}{host.dtype}".encode() + host.tobytes(), crc)
    return crc


def _check_same(args, program: int | None) -> None:
    """Every process must pass the same batch (each computes its rows from its own copy)
    to the same function (each runs its own compiled program): one fingerprint of each
    per process, compared across the processes (`program`: the program's fingerprint,
    None when nothing is compared)."""
    if program is None:
        return
    from jax.experimental import multihost_utils

    mine = np.array([_args_fingerprint(args), program], np.uint32)
    every = np.asarray(multihost_utils.process_allgather(mine)).reshape(-1, 2)
    if len(set(every[:, 0].tolist())) > 1:
        raise InputError(
            f"args differ between processes (fingerprints {every[:, 0].tolist()}, one per process); "
            "every process must call sweep with the same arguments, in the same order"
        )
    if len(set(every[:, 1].tolist())) > 1:
        prints = [f"{v:08x}" for v in every[:, 1].tolist()]
        raise InputError(
            f"fn differs between processes (program fingerprints {prints}, one per process): "
            "each process would compute its rows with its own function; pass every process "
            "the same function, closing over the same values (e.g. the same end time t1), "
            "built from the same settings on each"
        )


@one_failure_message
def sweep(
    fn: Callable[..., Any],
    *args: Any,
    in_axes: int | None | Sequence[int | None] = 0,
    devices: Sequence[jax.Device] | None = None,
    batch_size: int | None = None,
) -> Any:
    """Evaluate `fn` on every row of a batch: `jax.vmap(fn)`, sharded over devices.

    **Arguments:**

    - `fn`: a function of one row, e.g. `lambda kappa, k_r: simulate(Ball(kappa, k_r), y0, 2.0).ys["x"]`;
      it returns a pytree of arrays. Pass the *same* function object on later calls:
      the compiled program is cached per function, so new argument values do not
      recompile (`jaxunilat.debug.trace_counts()["sweep"]` counts the traces).
    - `*args`: the arguments; every leaf of a batched argument carries the batch
      along axis 0 (pytrees allowed, e.g. a `Ball` built under `jax.vmap`, whose
      leaves all have a leading axis).
    - `in_axes`: 0 (batched) or `None` (the same for every row), for all arguments
      or one entry per argument. Default 0.
    - `devices`: the devices to shard over. Default: all of `jax.devices()` (every
      process's devices after `jax.distributed.initialize()`; then every process must
      call `sweep` with the same function and arguments, else an `InputError` on every
      process, and each gets the whole result).
    - `batch_size`: `None` (default) sizes the batch to the devices' free memory: where
      `simulate` batches in lockstep (a GPU) a device vmaps all its rows at once if the
      compiled program (temp + output + argument bytes) fits in 60% (`HEADROOM`) of its
      free memory, else runs them in equal chunks (`lax.map`) of the most vmapped rows
      that fit beside every row's arguments and outputs (the per-row bytes: the slope
      between the program compiled for the whole batch and one for another size, an
      earlier sweep's or 32 rows: one extra compile, once per function and row shapes,
      only when the whole batch does not fit); a batch whose arguments and outputs alone
      do not fit is an `InputError`. On a CPU
      (`simulate` runs vmapped rows one by one) it vmaps all rows at once. An integer
      runs them in chunks of that many vmapped rows (`len(rows)`: all at once, whatever
      the memory). `1` runs the rows one after another, unbatched: each row's loop stops
      at its own last step (no lockstep behind the slowest row) and, after
      `use_loop_kernels()`, compiles into one CPU kernel. On a CPU that is the fastest
      for event-mode sweeps (README, Performance); on a GPU, vmap. On a CPU
      `simulate`'s batching rule runs its vmapped rows one by one anyway
      (`_batching.py`), so there all three run them alike.

    **Returns:** `fn`'s outputs stacked along a leading batch axis of the input's
    length (`jax.Array`s; NumPy arrays, on every process, when the devices span several
    processes). The batch is padded to a multiple of the device count with copies of its
    last row; the padding is removed from the result.
    """
    compiled, placed, n, n_pad = _prepare(fn, args, in_axes, devices, batch_size)
    out = _gather(compiled(*placed))
    if n_pad:
        out = jax.tree_util.tree_map(lambda leaf: leaf[:n], out)
    return out


def _prepare(fn, args, in_axes, devices, batch_size):
    if not callable(fn):
        raise InputError(f"fn = {fn!r} is not callable")
    axes = _normalize_axes(in_axes, len(args))
    devices = tuple(jax.devices() if devices is None else devices)
    if not devices:
        raise InputError("devices is empty; pass at least one device or None for all")
    if batch_size is not None and (not isinstance(batch_size, (int, np.integer)) or batch_size < 1):
        raise InputError(f"batch_size = {batch_size!r} is out of range; valid range is None or integers >= 1")
    n = _batch_size(args, axes)
    n_pad = -n % len(devices)
    if batch_size is None:
        batch_size, n_pad = _sized(fn, args, axes, devices, n)
    elif batch_size > 1 and batch_size >= (n + n_pad) // len(devices):
        batch_size = None  # one chunk: the same program as all rows at once
    _, batched, replicated = _program(fn, axes, devices, batch_size)
    placed = _place_all(args, axes, batched, replicated, n_pad)  # local: nothing runs yet
    return _executable(fn, axes, devices, batch_size, placed, args), placed, n, n_pad


# -- batch sizing ---------------------------------------------------------------------------


def _host_available() -> int:
    """The host's available memory, bytes (Linux's MemAvailable, else the free pages)."""
    try:
        with open("/proc/meminfo", encoding="ascii") as fh:
            for line in fh:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    try:
        return int(os.sysconf("SC_AVPHYS_PAGES")) * int(os.sysconf("SC_PAGE_SIZE"))
    except (AttributeError, OSError, ValueError):
        return HOST_CAP


def _free_bytes(devices) -> int:
    """Free memory of the tightest of this process's devices in `devices`, bytes: an
    accelerator's `bytes_limit - bytes_in_use`, a host device's share of the host's
    available memory (at most `HOST_CAP`, split between this process's host devices)."""
    mine = [d for d in devices if d.process_index == jax.process_index()] or list(devices)
    frees, host = [], 0
    for device in mine:
        try:
            stats = device.memory_stats()
        except Exception:  # noqa: BLE001  (a backend without statistics)
            stats = None
        if stats and "bytes_limit" in stats:
            frees.append(int(stats["bytes_limit"]) - int(stats.get("bytes_in_use", 0)))
        else:
            host += 1
    if host:
        frees.append(min(_host_available(), HOST_CAP) // host)
    return max(0, min(frees))


def _budget(devices) -> int:
    """The bytes a device's share of the batch may use: `HEADROOM` of its free memory; the
    smallest over the processes when they compare their programs (all must choose alike)."""
    budget = int(HEADROOM * _free_bytes(devices))
    if not _compared(devices):
        return budget
    from jax.experimental import multihost_utils

    every = multihost_utils.process_allgather(np.array([budget], np.int64))
    return int(np.min(np.asarray(every)))


def _total(mem) -> int:
    """A compiled program's bytes: temporaries, outputs and arguments (less aliased ones)."""
    return int(mem.temp_size_in_bytes + mem.output_size_in_bytes + mem.argument_size_in_bytes) - int(
        mem.alias_size_in_bytes
    )


def _kinds(mem) -> np.ndarray:
    return np.array([mem.temp_size_in_bytes, mem.output_size_in_bytes, mem.argument_size_in_bytes], float)


def chunk_rows(n_local: int, per_row, fixed: float, budget: float) -> int | None:
    """The rows a device vmaps at once: None for all `n_local`, else a chunk size.

    **Arguments:** `per_row`: (temp, output, argument) bytes per row; `fixed`: the bytes
    that do not grow with the rows; `budget`: the bytes the device may use.

    All rows fit if fixed + n_local · (temp + output + argument) <= budget. Else chunks
    of c rows need fixed + n_local · (output + argument) (every row's inputs and results)
    + c · (temp + output + argument) (a chunk's work and its slices), and c is the largest
    that fits, evened out so that equal chunks cover the rows (ceil(n_local / k) for k =
    ceil(n_local / c) chunks), rounded up to a multiple of `ALIGN` rows where c allows
    (then more chunks): a vectorized CPU loop computes its last rows apart, and aligned
    chunks of an aligned batch give its rows bit for bit. A batch whose arguments and
    outputs alone do not fit beside one row is an `InputError`.
    """
    temp, out, arg = (float(b) for b in per_row)
    row = temp + out + arg
    if row <= 0.0 or fixed + n_local * row <= budget:
        return None
    c = math.floor((budget - fixed - n_local * (out + arg)) / row)
    if c < 1:
        need = fixed + n_local * (out + arg) + row
        raise InputError(
            f"a batch of {n_local} rows per device needs {need / 2**30:.3g} GiB per device for its "
            f"arguments and outputs alone, more than the {budget / 2**30:.3g} GiB sweep may use "
            f"({HEADROOM:.0%} of the free memory); sweep fewer rows per call, over more devices, "
            "or with fewer outputs per row (or pass batch_size to run anyway)"
        )
    k = math.ceil(n_local / c)
    while True:
        chunk = math.ceil(n_local / k)
        if c >= ALIGN:
            chunk = ALIGN * math.ceil(chunk / ALIGN)
        if chunk <= c:
            return chunk
        k += 1


def _row_key(fn, axes, devices, args) -> tuple:
    """(fn, axes, device ids, the batched leaves' row types, the other leaves' types)."""
    key: list = [fn, axes, tuple(d.id for d in devices)]
    for arg, axis in zip(args, axes, strict=True):
        leaves, treedef = jax.tree_util.tree_flatten(arg)
        key.append(treedef)
        for leaf in leaves:
            a = np.asarray(leaf) if not isinstance(leaf, jax.Array) else leaf
            shape = np.shape(a)[1:] if axis == 0 else np.shape(a)
            key.append((shape, str(a.dtype)))
    return tuple(key)


def _probe(fn, axes, devices, args, rows: int):
    """The memory analysis of the vmapped program for `rows` rows per device (compiled from
    the arguments' types alone: nothing is placed)."""
    jitted, batched, replicated = _program(fn, axes, devices, None)

    def struct(leaf, axis):
        a = leaf if isinstance(leaf, jax.Array) else jnp.asarray(leaf)
        if axis == 0:
            return jax.ShapeDtypeStruct((rows * len(devices), *a.shape[1:]), a.dtype, sharding=batched)
        return jax.ShapeDtypeStruct(a.shape, a.dtype, sharding=replicated, weak_type=jax.typeof(a).weak_type)

    structs = tuple(
        jax.tree_util.tree_map(lambda leaf, axis=axis: struct(leaf, axis), arg)
        for arg, axis in zip(args, axes, strict=True)
    )
    return jitted.lower(*structs).compile().memory_analysis()


def _sized(fn, args, axes, devices, n: int) -> tuple[int | None, int]:
    """`sweep`'s batch for `batch_size=None`: (rows a device vmaps at once, None for all;
    the padding rows), see the module's docstring."""
    d = len(devices)
    n_pad = -n % d
    n_local = (n + n_pad) // d
    if batching_mode() != "batch" or n_local <= _SMALL:
        return None, n_pad
    key = _row_key(fn, axes, devices, args)
    budget = _budget(devices)
    chosen = _CHOSEN.get((key, n_local))
    if chosen is not None and chosen[1] <= budget:
        return chosen[0], _padding(n, d, chosen[0])
    if key not in _SIZING:
        _, batched, replicated = _program(fn, axes, devices, None)
        placed = _place_all(args, axes, batched, replicated, n_pad)
        full = _executable(fn, axes, devices, None, placed, args).memory_analysis()
        if full is None:  # no memory analysis: all at once, as without sizing
            return None, n_pad
        points = _POINTS.setdefault(key, {})
        points[n_local] = full
        if _total(full) <= budget:
            _CHOSEN[(key, n_local)] = (None, _total(full))
            return None, n_pad
        # The slope to another batch size's program: one measured before (a sweep of
        # another size), else one compiled for `_PROBE` rows.
        other = max((m for m in points if m != n_local), default=None)
        if other is None:
            other = _PROBE
            points[other] = _probe(fn, axes, devices, args, other)
        per_row = np.maximum((_kinds(full) - _kinds(points[other])) / (n_local - other), 0.0)
        fixed = max(0.0, _total(points[other]) - other * float(np.sum(per_row)))
        _SIZING[key] = (tuple(float(b) for b in per_row), fixed)
    per_row, fixed = _SIZING[key]
    chunk = chunk_rows(n_local, per_row, fixed, budget)
    temp, out, arg = per_row
    rows = n_local if chunk is None else chunk
    need = fixed + n_local * (out + arg) + rows * (temp + (0.0 if chunk is None else out + arg))
    _CHOSEN[(key, n_local)] = (chunk, need)
    return chunk, _padding(n, d, chunk)


def _padding(n: int, d: int, chunk: int | None) -> int:
    """Padding rows for n rows on d devices in equal chunks of `chunk` rows per device."""
    if chunk is None:
        return -n % d
    n_local = -(-n // d)
    return d * chunk * math.ceil(n_local / chunk) - n


def sweep_compiled(fn: Callable[..., Any], *args: Any, in_axes=0, devices=None, batch_size=None):
    """The compiled program that `sweep` runs for these arguments (compiling it if needed).

    **Returns:** a `jax.stages.Compiled`; its `memory_analysis()` gives the argument,
    output and temporary buffer sizes.
    """
    return _prepare(fn, args, in_axes, devices, batch_size)[0]


def batch_rows(fn: Callable[..., Any], *args: Any, in_axes=0, devices=None) -> int:
    """The rows a device vmaps at once in `sweep(fn, *args, batch_size=None)`: all of its
    rows, or the chunk that the free memory allows (compiling to measure, as `sweep` does)."""
    axes = _normalize_axes(in_axes, len(args))
    devices = tuple(jax.devices() if devices is None else devices)
    n = _batch_size(args, axes)
    chunk, n_pad = _sized(fn, args, axes, devices, n)
    return (n + n_pad) // len(devices) if chunk is None else chunk
