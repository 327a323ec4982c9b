"""Optional dependencies: import one on first use, or fail saying which extra installs it."""
from __future__ import annotations

import importlib
from types import ModuleType

__all__ = ["optional_import"]


def optional_import(module: str, purpose: str, extra: str = "experiments") -> ModuleType:
    """``module`` imported, or an ImportError "``purpose``: ``module`` is not installed; pip install
    'pathspace[extra]'"."""
    try:
        return importlib.import_module(module)
    except ImportError:
        raise ImportError(f"{purpose}: {module.split('.')[0]} is not installed; "
                          f"pip install 'pathspace[{extra}]'") from None
