"""foottof: quadruped locomotion over discrete terrain with foot-mounted ToF sensing (JAX + MJX).

Side effect on purpose: a sys.meta_path hook, set before mujoco.mjx's import prints warp lines.
"""

import contextlib
import importlib.abc
import io
import sys

__version__ = "0.1.0"

# MJX imports its optional Warp backend (mujoco.mjx.warp) and print()s one line per missing
# package. We never use Warp, so exactly these lines are dropped (only when Warp is absent: a
# Warp that is installed but fails to load still says so); anything else printed is kept.
WARP_ABSENT_LINES = (
    "Failed to import warp: No module named 'warp'",
    "Failed to import mujoco_warp: No module named 'warp'",
)
_WARP_MODULE = "mujoco.mjx.warp"


def drop_warp_absent_lines(text: str) -> str:
    """`text` without the lines MJX prints when the optional Warp package is not installed."""
    return "".join(
        line
        for line in text.splitlines(keepends=True)
        if line.rstrip("\r\n") not in WARP_ABSENT_LINES
    )


class _QuietLoader(importlib.abc.Loader):
    """Runs the wrapped loader with stdout filtered by drop_warp_absent_lines."""

    def __init__(self, loader):
        self._loader = loader

    def create_module(self, spec):
        return self._loader.create_module(spec)

    def exec_module(self, module):
        buf = io.StringIO()
        try:
            with contextlib.redirect_stdout(buf):
                self._loader.exec_module(module)
        finally:
            sys.stdout.write(drop_warp_absent_lines(buf.getvalue()))

    def __getattr__(self, name):  # get_resource_reader, is_package, ...
        return getattr(self._loader, name)


class _QuietWarpFinder(importlib.abc.MetaPathFinder):
    """Finds mujoco.mjx.warp with the other finders and wraps its loader in _QuietLoader."""

    def find_spec(self, fullname, path, target=None):
        if fullname != _WARP_MODULE:
            return None
        for finder in sys.meta_path:
            if finder is self or not hasattr(finder, "find_spec"):
                continue
            spec = finder.find_spec(fullname, path, target)
            if spec is not None:
                if spec.loader is not None:
                    spec.loader = _QuietLoader(spec.loader)
                return spec
        return None


if not any(isinstance(f, _QuietWarpFinder) for f in sys.meta_path):
    sys.meta_path.insert(0, _QuietWarpFinder())
