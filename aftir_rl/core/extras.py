"""Optional dependencies (the wheel's extras): import one, or say in one line how to get it."""

from __future__ import annotations

import importlib
from types import ModuleType

from aftir_rl.core.errors import MissingExtraError

__all__ = ["require"]


def require(module: str, extra: str) -> ModuleType:
    """Import ``module``; if it is missing, raise :class:`MissingExtraError` naming ``extra``."""
    try:
        return importlib.import_module(module)
    except ImportError:
        raise MissingExtraError(
            f'{module} is not installed; pip install "aftir_rl[{extra}]"'
        ) from None
