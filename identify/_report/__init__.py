"""The report layer: the `FitResult` (report text, JSON), the summary of a finished fit,
and the figures (`identify.plot` is their public face).

Imports `identify._data` and `identify._fit`.
"""
