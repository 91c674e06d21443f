"""Config files (ml_collections). Each file defines get_config(); sections live in configs/_*.py."""
