"""Moved to foottof.ppo.storage.input_growth; this name stays importable as the same module (CHANGELOG.md)."""

import sys

from foottof.ppo.storage import input_growth as _moved

sys.modules[__name__] = _moved
