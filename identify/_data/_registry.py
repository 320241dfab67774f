"""The importers `jaxunilat import` offers, in the order its help lists them.

Each importer module declares one `_import.Importer` (its name, aliases, help, flags and
how to run it); the command line (`identify._cli._import`) builds one subcommand per
entry. Adding an importer is adding its module and its line here.
"""

from __future__ import annotations

from ._import import Importer
from ._import_audio import WAV
from ._import_phyphox import PHYPHOX
from ._import_video import VIDEO

#: Every importer, as `jaxunilat import --help` lists them.
IMPORTERS: tuple[Importer, ...] = (WAV, PHYPHOX, VIDEO)


def importer_named(name: str) -> Importer:
    """The importer whose name or alias is `name` (`KeyError` if none)."""
    for importer in IMPORTERS:
        if name == importer.name or name in importer.aliases:
            return importer
    raise KeyError(name)
