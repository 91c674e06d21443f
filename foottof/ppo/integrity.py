"""Moved to foottof.ppo.storage.integrity; this name stays importable as the same module (CHANGELOG.md)."""

import sys

from foottof.ppo.storage import integrity as _moved

sys.modules[__name__] = _moved
