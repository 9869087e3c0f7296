"""A module that is also callable as the function of the same name it defines.

``fusionkit.simulate`` and ``fusionkit.resample`` each name both a module and the function it
defines (the package exports the functions lazily). Once any code has imported the module,
Python's import system binds the package attribute to the module, in place of the function;
calling the module calls the function, so ``fusionkit.resample(grid, t, canvas)`` works
whichever of the two the name holds.
"""

from __future__ import annotations

import inspect
import sys
import types

__all__ = ["callable_as"]


def callable_as(module_name: str, function: str) -> None:
    """Make the module ``module_name`` callable as its function ``function``."""

    class _CallableModule(types.ModuleType):
        def __call__(self, *args, **kwargs):
            return getattr(self, function)(*args, **kwargs)

    _CallableModule.__doc__ = f"This module, callable as its function {function}."
    module = sys.modules[module_name]
    module.__class__ = _CallableModule
    # inspect.signature (and so a notebook's call tips) shows the function's parameters
    module.__signature__ = inspect.signature(getattr(module, function))
