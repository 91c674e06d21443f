"""Config files (ml_collections). Each file defines get_config(); sections live in configs/_*.py."""

import importlib.util


def load_config(path: str):
    """``get_config()`` of a config file by path (e.g. 'configs/cpu.py'), for scripts without flags."""
    spec = importlib.util.spec_from_file_location("foottof_config", path)
    if spec is None:
        raise FileNotFoundError(f"config file {path!r} not found")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod.get_config()
