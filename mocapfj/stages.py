"""Stage packages that can be called: ``mocapfj.joints(rec)`` and ``mocapfj.discover(rec, ...)`` run
the API functions of the same name (:mod:`mocapfj.api`) while ``mocapfj.joints`` and
``mocapfj.discover`` stay the packages that hold the stages' code."""

from __future__ import annotations

import sys
from importlib import import_module
from types import ModuleType

__all__ = ["StageModule", "make_stage_callable"]


class StageModule(ModuleType):
    """A package whose call runs the API function named like it (looked up in mocapfj.api when
    called, so the package does not import the API that imports it)."""

    def __call__(self, *args, **kw):
        return getattr(import_module("mocapfj.api"), self.__name__.rsplit(".", 1)[-1])(*args, **kw)


def make_stage_callable(module_name: str) -> None:
    """Make the package `module_name` callable as the API function of the same name."""
    sys.modules[module_name].__class__ = StageModule
