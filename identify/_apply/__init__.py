"""Using a fit: the rebound qualification of a ball and the MuJoCo contact export.

Both read a fit's JSON (or a `FitResult`'s); they import no other layer of identify.
"""
