"""JSON Schema of every input file kind (``mobisense schema KIND``), generated from its pydantic model.

Editors with a YAML language server complete and check a file given its schema, e.g. with the first
line ``# yaml-language-server: $schema=problem.schema.json`` after
``mobisense schema problem --out problem.schema.json``. The parts of a file whose keys depend on a
registered name (a sensor's ``noise`` by its ``model``, a field replay's ``formation`` and ``motion`` by
their ``kind``) become a ``oneOf`` over the registered models, so an installed noise model appears too.
"""

from __future__ import annotations

from typing import Any

from .kinds import FILE_KINDS, kind_model, load_target

__all__ = ["file_schema", "JSON_SCHEMA_DIALECT"]

JSON_SCHEMA_DIALECT = "https://json-schema.org/draft/2020-12/schema"
_REF = "#/$defs/{model}"


def _variant(model: Any, key: str, name: str, definitions: dict[str, Any]) -> dict[str, Any]:
    schema = model.model_json_schema(ref_template=_REF)
    definitions.update(schema.pop("$defs", {}))
    schema.setdefault("properties", {})[key] = {"const": name, "description": f"{key}: {name}"}
    schema["required"] = sorted({*schema.get("required", []), key})
    return schema


def file_schema(kind: str) -> dict[str, Any]:
    """The JSON Schema (draft 2020-12) of files of ``kind`` (a key of :data:`~mobisense.core.kinds.FILE_KINDS`)."""
    entry = FILE_KINDS[kind]
    schema = kind_model(kind).model_json_schema(ref_template=_REF)
    definitions = schema.setdefault("$defs", {})
    for path, (key, registry_name) in entry.variants.items():
        registry = load_target(registry_name)
        variants = [_variant(registry[name], key, name, definitions) for name in sorted(registry)]
        parent, _, leaf = path.rpartition("/")
        node: dict[str, Any] = schema
        for part in parent.split("/"):
            node = node[part]
        description = node.get(leaf, {}).get("description")
        node[leaf] = {"oneOf": variants, **({"description": description} if description else {})}
    if not definitions:
        schema.pop("$defs")
    head = {
        "$schema": JSON_SCHEMA_DIALECT,
        "title": f"mobisense {kind} file",
        "description": f"{entry.title.capitalize()} file, read by `{entry.command}`. "
        + schema.get("description", ""),
    }
    return {**head, **{k: v for k, v in schema.items() if k not in head}}
