"""Camera model and projection, calibration targets, detection, calibration, triangulation and tracking.

See docs/architecture.md for what this package owns and may import.
"""
