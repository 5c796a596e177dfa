"""Identification: signal conditioning, least squares with statistics, the two-step method, spring models, excitation, FRF.

See docs/architecture.md for what this package owns and may import.
"""
