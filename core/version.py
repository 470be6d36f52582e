"""The version of mobisense (read by pyproject, printed by ``--version``, written into every output file)."""

__version__ = "0.2.0"
