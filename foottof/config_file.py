"""Loading a config file (configs/*.py) by path, for tools without flags (imports no JAX)."""

import importlib.util


def load_config(path: str):
    """``get_config()`` of a config file by path (e.g. 'configs/cpu.py').

    The repo's config files import their sections (``from configs import base``): run from the
    repo root, or with it on ``sys.path``.

    Raises:
      FileNotFoundError: no config file at ``path``.
    """
    spec = importlib.util.spec_from_file_location("foottof_config", path)
    if spec is None:
        raise FileNotFoundError(f"config file {path!r} not found")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod.get_config()
