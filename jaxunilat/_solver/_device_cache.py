"""`DeviceCache`: a small LRU cache of values kept on the device.

`simulate` builds a few things from plain numbers on every call (the solver settings,
the default save times); built once and kept on the device, a repeated call neither
rebuilds nor copies them (together ~0.1 ms of a 0.35 ms call).
"""

from __future__ import annotations

from collections import OrderedDict
from collections.abc import Callable, Hashable
from typing import Any

import jax


class DeviceCache:
    """An LRU cache of pytrees whose array leaves are placed on the device.

    A value built inside a transformation (`jax.jit`, `jax.vmap`: `device_put` then
    gives that trace's tracers) is returned but not kept, so no tracer leaks into a
    later call.
    """

    def __init__(self, size: int):
        self._values: OrderedDict = OrderedDict()
        self._size = size

    def get(self, key: Hashable, build: Callable[[], Any]) -> Any:
        """The value for `key`, from `build()` the first time (per default device: a value
        kept for the host is not handed to a call placed on an accelerator)."""
        key = (key, jax.config.jax_default_device)
        value = self._values.get(key)
        if value is not None:
            self._values.move_to_end(key)
            return value
        value = jax.tree_util.tree_map(jax.device_put, build())
        if any(isinstance(leaf, jax.core.Tracer) for leaf in jax.tree_util.tree_leaves(value)):
            return value
        self._values[key] = value
        if len(self._values) > self._size:
            self._values.popitem(last=False)
        return value
