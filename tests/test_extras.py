"""Optional dependencies fail with the extra that installs them."""
from __future__ import annotations

import pytest

from pathspace.extras import optional_import


def test_a_missing_extra_names_its_install_command():
    assert optional_import("json", "tables").dumps([]) == "[]"
    with pytest.raises(ImportError, match=r"figures: no_such_module is not installed; pip install 'pathspace\[experiments\]'"):
        optional_import("no_such_module.pyplot", "figures")
