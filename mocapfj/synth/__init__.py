"""Synthetic recordings whose truth is known (docs/formats.md for the bundle they produce)."""

from .toy import TOY_TRUTH, toy_recording

__all__ = ["toy_recording", "TOY_TRUTH"]
