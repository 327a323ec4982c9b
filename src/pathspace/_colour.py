"""colour-science, imported once and quietly.

Without matplotlib installed, colour-science warns at import that its
plotting API is unavailable; pathspace does not use that API.
"""
import warnings

with warnings.catch_warnings():
    warnings.filterwarnings("ignore", message='.*"Matplotlib" related API features are not available.*')
    import colour  # noqa: E402

__all__ = ["colour"]
