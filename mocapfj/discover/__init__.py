"""Mismatch discovery: locate what a simulation misses, name the physics, model it, prove the fit improves.

See docs/architecture.md for what this package owns and may import.
"""
