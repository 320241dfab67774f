"""Public names imported on first use: the module `__getattr__` and `__dir__` of a package
whose `__init__` lists each name with the module that defines it (PEP 562).

`jaxunilat`, `jaxunilat._internal` and `jaxunilat.identify` use it, so that the command
line's light paths (`jaxunilat --help`) import no JAX. Imports nothing but the standard
library.
"""

from __future__ import annotations

import importlib
import sys
from collections.abc import Callable, Iterable, Mapping


def lazy_names(
    package: str, names: Mapping[str, str], namespaces: Iterable[str] = ()
) -> tuple[Callable[[str], object], Callable[[], list[str]]]:
    """`(__getattr__, __dir__)` for `package` (its `__name__`): `names` maps each public
    name to the module that defines it (relative, e.g. "._models"), `namespaces` are
    subpackages imported when first used. A value found is kept in the package's globals,
    so the look-up runs once per name."""
    namespaces = tuple(namespaces)

    def __getattr__(name: str):
        if name in namespaces:
            value = importlib.import_module(f".{name}", package)
        elif name in names:
            value = getattr(importlib.import_module(names[name], package), name)
        else:
            raise AttributeError(f"module {package!r} has no attribute {name!r}")
        setattr(sys.modules[package], name, value)
        return value

    def __dir__() -> list[str]:
        return sorted({*vars(sys.modules[package]), *names, *namespaces})

    return __getattr__, __dir__
