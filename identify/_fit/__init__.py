"""The fit layer: the model's predictions, the joint set-up, the Levenberg–Marquardt and
the fit's stages, the uncertainty, the restitution maths and the closed-form gate.

Imports only `identify._data` (never `identify._report`).
"""
