"""The data layer: the `jaxunilat-data` format and the importers (WAV, phyphox, video: `_registry`).

Imports nothing else of identify: it parses and detects, and knows no model.
"""

from ._format import Dataset, format_dataset, load_dataset, write_dataset

__all__ = ["Dataset", "format_dataset", "load_dataset", "write_dataset"]
