"""Moved to foottof.ppo.storage.run_dir; this name stays importable as the same module (CHANGELOG.md)."""

import sys

from foottof.ppo.storage import run_dir as _moved

sys.modules[__name__] = _moved
