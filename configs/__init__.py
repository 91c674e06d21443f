"""Config files (ml_collections). Each file defines get_config(); sections live in configs/_*.py."""

from foottof.config_file import load_config  # noqa: F401 (scripts and tests load configs by path)
