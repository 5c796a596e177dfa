"""Joint axes and centres from marker clusters, per-frame link angles, stream synchronisation and deflection.

See docs/architecture.md for what this package owns and may import.
"""
