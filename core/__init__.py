"""Plumbing every package may use: validated configuration files, registries, key paths, atomic outputs."""

from .lazy import lazy_exports

__getattr__, __dir__, __all__ = lazy_exports(
    __name__,
    {
        "ConfigError": "mobisense.core.config",
        "InvalidValue": "mobisense.core.config",
        "StrictModel": "mobisense.core.config",
        "load_config": "mobisense.core.config",
        "parse_config": "mobisense.core.config",
        "read_yaml": "mobisense.core.config",
        "atomic_path": "mobisense.core.files",
        "write_json": "mobisense.core.files",
        "write_netcdf": "mobisense.core.files",
        "write_figure": "mobisense.core.files",
        "open_dataset": "mobisense.core.netcdf",
        "UnitSystem": "mobisense.core.units",
        "get_path": "mobisense.core.keypath",
        "set_path": "mobisense.core.keypath",
        "parse_key_path": "mobisense.core.keypath",
        "Registry": "mobisense.core.registry",
        "Lazy": "mobisense.core.registry",
        "default_output_folder": "mobisense.core.output",
        "lazy_exports": "mobisense.core.lazy",
    },
)
