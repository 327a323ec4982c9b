"""Progress bars for long work (tqdm: a widget in Jupyter, a line in a terminal)."""
from __future__ import annotations

__all__ = ["progress_bar"]


def progress_bar(enabled: bool, total: int | None, unit: str, description: str, initial: int = 0):
    """A tqdm bar of ``total`` ``unit`` s from ``initial``, or None when not ``enabled``."""
    if not enabled:
        return None
    from tqdm.auto import tqdm

    return tqdm(total=total, initial=initial, unit=unit, desc=description, dynamic_ncols=True)
