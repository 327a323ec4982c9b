"""The error raised for bad scene input."""
from __future__ import annotations


class SceneError(ValueError):
    """A scene file or scene description is invalid.

    The message names the file, the field (as a path such as
    ``shapes[2].emitter.radiance``) and what was expected.
    """
