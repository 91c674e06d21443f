"""Moved to foottof.ppo.storage.checkpoint; this name stays importable as the same module (CHANGELOG.md)."""

import sys

from foottof.ppo.storage import checkpoint as _moved

sys.modules[__name__] = _moved
