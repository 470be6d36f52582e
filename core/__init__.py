"""Plumbing every package may use: input files, the pre-flight budget, output folders, registries, key paths.

The one reader of input files and validated configurations, the memory/time budget checked before any work,
checked and locked output folders with atomic files, registries of named implementations, key paths.
"""

from .lazy import lazy_exports

__getattr__, __dir__, __all__ = lazy_exports(
    __name__,
    {
        "ConfigError": "mobisense.core.config",
        "ComputationError": "mobisense.core.errors",
        "OutputError": "mobisense.core.errors",
        "read_document": "mobisense.core.reader",
        "Estimate": "mobisense.core.budget",
        "check_budget": "mobisense.core.budget",
        "default_memory_limit": "mobisense.core.budget",
        "OutputFolder": "mobisense.core.output",
        "deferred_interrupts": "mobisense.core.interrupts",
        "InvalidValue": "mobisense.core.config",
        "StrictModel": "mobisense.core.config",
        "load_config": "mobisense.core.config",
        "parse_config": "mobisense.core.config",
        "read_yaml": "mobisense.core.config",
        "atomic_path": "mobisense.core.files",
        "write_json": "mobisense.core.files",
        "write_netcdf": "mobisense.core.files",
        "DatasetContent": "mobisense.core.netcdf_writer",
        "write_content": "mobisense.core.netcdf_writer",
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
