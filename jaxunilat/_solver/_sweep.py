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
"""

from __future__ import annotations

import zlib
from collections.abc import Callable, Sequence
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np
from jax.sharding import Mesh, NamedSharding, PartitionSpec

from ..internal._errors import InputError
from ._simulate import _TRACES

AXIS = "batch"

#: (fn, in_axes, device ids) -> (the jitted sharded vmapped function, batched and
#: replicated shardings); and (that key, argument types) -> (its compiled executable,
#: its program fingerprint or None on one process).
_CACHE: dict[tuple, tuple] = {}
_EXECUTABLES: dict[tuple, tuple] = {}


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
    - `batch_size`: `None` vmaps all of a device's rows at once; an integer runs them
      in chunks of that many vmapped rows (`lax.map`), which bounds memory for large
      batches (a vmapped while loop holds every row's buffers). `1` runs the rows one
      after another, unbatched: each row's loop stops at its own last step (no
      lockstep behind the slowest row) and, after `use_loop_kernels()`, compiles into
      one CPU kernel. On a CPU that is the fastest for event-mode sweeps (README,
      Performance); on a GPU, vmap. On a CPU `simulate`'s batching rule runs its vmapped
      rows one by one anyway (`_batching.py`), so there all three run them alike.

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
    _, batched, replicated = _program(fn, axes, devices, batch_size)
    placed = _place_all(args, axes, batched, replicated, n_pad)  # local: nothing runs yet
    return _executable(fn, axes, devices, batch_size, placed, args), placed, n, n_pad


def sweep_compiled(fn: Callable[..., Any], *args: Any, in_axes=0, devices=None, batch_size=None):
    """The compiled program that `sweep` runs for these arguments (compiling it if needed).

    **Returns:** a `jax.stages.Compiled`; its `memory_analysis()` gives the argument,
    output and temporary buffer sizes.
    """
    return _prepare(fn, args, in_axes, devices, batch_size)[0]
