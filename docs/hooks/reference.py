"""Generated reference pages of the documentation site (used by ``docs/hooks/hooks.py``).

* :func:`cli_reference` — every command and option, from the argument parser of ``mobisense``;
* :func:`input_reference` — every input file kind, from the JSON Schema of its pydantic model;
* :func:`output_reference` — every output file: the datasets are produced by short runs of the real
  code (small grids, short horizons), written with the real writer and read back, so the page lists
  exactly the variables, dimensions, units and attributes a user's files have;
* :func:`api_pages` — one page per subpackage, each public module rendered by mkdocstrings.
"""

from __future__ import annotations

import argparse
import json
import tempfile
from pathlib import Path
from typing import Any

import yaml

ROOT = Path(__file__).resolve().parents[2]


def _cell(text: Any) -> str:
    return str(text).replace("``", "`").replace("|", "\\|").replace("\n", " ")


# ----------------------------------------------------------------------------------------- CLI
def cli_reference() -> str:
    """Markdown of every sub-command: usage, description and a table of its arguments."""
    from mobisense.cli import build_parser

    parser = build_parser()
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    lines = [
        "# Command-line reference",
        "",
        "Generated from the argument parser of `mobisense` (`mobisense COMMAND --help` prints the same).",
        "Exit status: 0 success, 1 solver or simulation failure (results so far are kept), 2 invalid input",
        "(one line naming the file and the key path, nothing written), 130 interrupted (Ctrl-C or SIGTERM;",
        "a solve stops within one Ipopt iteration, a replay within one step).",
        "",
        "Every command that reads a file also accepts the name of a shipped example "
        "(`mobisense solve hussein2008`; see `mobisense examples`).",
        "",
    ]
    for name, command in sub.choices.items():
        lines += [f"## `mobisense {name}`", "", command.description or "", "", "```text",
                  command.format_usage().strip(), "```", "",
                  "| argument | meaning | default |", "|---|---|---|"]  # fmt: skip
        for action in command._actions:
            if isinstance(action, argparse._HelpAction):
                continue
            flags = ", ".join(f"`{f}`" for f in action.option_strings) or f"`{action.dest}`"
            if action.choices:
                flags += " {" + ", ".join(map(str, action.choices)) + "}"
            default = "" if action.default in (None, False, argparse.SUPPRESS) else f"`{action.default}`"
            lines.append(f"| {flags} | {_cell(action.help or '')} | {default} |")
        lines.append("")
    return "\n".join(lines)


# -------------------------------------------------------------------------------------- inputs
def _resolve(schema: dict[str, Any], node: dict[str, Any]) -> dict[str, Any]:
    while "$ref" in node:
        node = {**schema["$defs"][node["$ref"].split("/")[-1]], **{k: v for k, v in node.items() if k != "$ref"}}
    return node


def _type(schema: dict[str, Any], node: dict[str, Any]) -> str:
    node = _resolve(schema, node)
    if "const" in node:
        return f"`{node['const']!r}`"
    if "enum" in node:
        return " | ".join(f"`{v!r}`" for v in node["enum"])
    for key in ("anyOf", "oneOf"):
        if key in node:
            return " or ".join(_type(schema, n) for n in node[key])
    kind = node.get("type", "any")
    if kind == "array":
        return f"list of {_type(schema, node.get('items', {}))}"
    if kind == "object" and "properties" in node:
        return f"mapping ({node.get('title', 'object')})"
    return str(kind)


def _rows(schema: dict[str, Any], node: dict[str, Any], prefix: str, required: bool) -> list[str]:
    node = _resolve(schema, node)
    variants = node.get("oneOf") or [n for n in node.get("anyOf", []) if "properties" in _resolve(schema, n)]
    if variants:
        out = []
        for variant in variants:
            variant = _resolve(schema, variant)
            tag = next((f"{k} = {p['const']!r}" for k, p in variant.get("properties", {}).items() if "const" in p), "")
            out += _rows(schema, variant, f"{prefix} ({tag})" if tag else prefix, required)
        return out
    rows = []
    needed = set(node.get("required", []))
    for key, sub in node.get("properties", {}).items():
        path = f"{prefix}.{key}" if prefix else key
        resolved = _resolve(schema, sub)
        default = "required" if key in needed else f"`{json.dumps(sub.get('default', resolved.get('default')))}`"
        description = sub.get("description") or resolved.get("description", "")
        description = description.split("\n\n")[0]
        rows.append(f"| `{path}` | {_cell(_type(schema, sub))} | {default} | {_cell(description)} |")
        if "properties" in resolved or "oneOf" in resolved or any(
            "properties" in _resolve(schema, n) for n in resolved.get("anyOf", [])
        ):
            rows += _rows(schema, resolved, path, key in needed)
        elif resolved.get("type") == "array" and "properties" in _resolve(schema, resolved.get("items", {})):
            rows += _rows(schema, resolved["items"], f"{path}[i]", key in needed)
    return rows


def input_reference() -> str:
    """Markdown of every input file kind: how it is recognised, its command, examples and every key."""
    from mobisense.core.examples import EXAMPLES
    from mobisense.core.kinds import FILE_KINDS, detect_kind
    from mobisense.core.schema import file_schema

    kinds: dict[str, list[str]] = {}
    for example in EXAMPLES:
        data = yaml.safe_load((ROOT / "problems" / f"{example.name}.yaml").read_text(encoding="utf-8"))
        kinds.setdefault(detect_kind(data, example.name), []).append(example.name)
    lines = [
        "# Input files",
        "",
        "Every input is a YAML file of one of the kinds below, generated from the pydantic models that validate",
        "them. A file may say what it is with a top-level `kind:` key (optional for problem files); otherwise its",
        "shape tells (`mobisense validate FILE` prints which kind it found). Unknown keys are errors, with the",
        "closest allowed key suggested.",
        "",
        "Editors complete and check these files from their JSON Schema: `mobisense schema KIND --out",
        "KIND.schema.json`, then start the YAML file with `# yaml-language-server: $schema=KIND.schema.json`",
        "(VS Code's YAML extension, or any editor with the YAML language server).",
        "",
        "Units: problem files and field replays may declare `units: {length: m, time: s}` (defaults metre and",
        "second; `'1'` for a dimensionless axis); every output variable's `units` attribute follows from them.",
        "",
    ]
    for name, kind in FILE_KINDS.items():
        schema = file_schema(name)
        examples = ", ".join(f"`problems/{e}.yaml`" for e in kinds.get(name, [])) or "none"
        lines += [
            f"## `{name}` — {kind.title}", "", f"Run with `{kind.command}`. Shipped examples: {examples}.", "",
            _cell(schema.get("description", "")), "",
            f"JSON Schema: `mobisense schema {name}`.", "",
            "| key | type | default | meaning |", "|---|---|---|---|",
            *_rows(schema, schema, "", True), "",
        ]  # fmt: skip
    return "\n".join(lines)


# ------------------------------------------------------------------------------------- outputs
def _problem(folder: Path) -> Path:
    data = yaml.safe_load((ROOT / "problems" / "hussein2008.yaml").read_text(encoding="utf-8"))
    data["solver"]["collocation"]["intervals"] = 10
    data["solver"]["homotopy"]["step"] = 0.5
    path = folder / "problem.yaml"
    path.write_text(yaml.safe_dump(data), encoding="utf-8")
    return path


def _example_outputs(folder: Path) -> dict[str, tuple[Path, str]]:
    """Run each command on a shortened example; return output name -> (folder, command that writes it)."""
    import mobisense as ms
    from mobisense.estimation.cooperative.design_study import design_formation
    from mobisense.formation.scenarios import load_scenario

    out: dict[str, tuple[Path, str]] = {}
    problem = _problem(folder)
    ms.solve(ms.load_problem(problem)).save(folder / "solve")
    out["solve"] = (folder / "solve", "mobisense solve")
    replay = folder / "replay_plan.yaml"
    replay.write_text(yaml.safe_dump({"name": "plan", "solution": "solve/solution.nc", "problem": "problem.yaml",
                                      "monte_carlo": {"runs": 20, "time_step": 0.1}}), encoding="utf-8")  # fmt: skip
    shortened = {
        "replay_plan": (replay, {}),
        "replay_field": (ROOT / "problems" / "replay_two_charges.yaml", {"duration": 1.0}),
        "leader_follower": (ROOT / "problems" / "leader_follower_khepera.yaml", {"duration": 0.2}),
        "distributed": (ROOT / "problems" / "distributed_advection_diffusion.yaml", {"time": {"duration": 3.0}}),
    }
    commands = {"replay_plan": "mobisense replay", "replay_field": "mobisense replay",
                "leader_follower": "mobisense simulate leader-follower",
                "distributed": "mobisense simulate distributed"}  # fmt: skip
    for name, (source, changes) in shortened.items():
        data = yaml.safe_load(source.read_text(encoding="utf-8"))
        data.update(changes)
        path = folder / f"{name}.yaml"
        path.write_text(yaml.safe_dump(data, allow_unicode=True), encoding="utf-8")
        kind = {"leader_follower": "leader_follower", "distributed": "distributed"}.get(name, "replay")
        load_scenario(path, kind).run().save(folder / name, figures=False)
        out[name] = (folder / name, commands[name])
    formation = yaml.safe_load((ROOT / "problems" / "formation_cross.yaml").read_text(encoding="utf-8"))
    formation["contour_resolution"] = 11
    (folder / "formation.yaml").write_text(yaml.safe_dump(formation), encoding="utf-8")
    design_formation(folder / "formation.yaml").save(folder / "steady_state", figures=False)
    out["steady_state"] = (folder / "steady_state", "mobisense steady-state")
    return out


#: global attribute -> meaning (the output reference lists these for every file that has them)
ATTRIBUTES = {
    "Conventions": "`CF-1.10`", "title": "what the file holds", "history": "UTC time, command line and version",
    "source": "mobisense and its version", "comment": "conventions of the data (matrix storage, units)",
    "nlp_signature": "structure of the NLP the warm-start point belongs to",
    "problem_yaml": "the normalised problem, every default filled in", "solver_options_json": "the solver options",
    "summary_json": "summary.json", "homotopy_json": "every ε step (ε, J_ε, iterations, status, time)",
    "baseline_json": "the no-control baseline's cost split", "stats_json": "solver statistics",
    "method": "direct, indirect or both", "status": "solved / failed (or ok / what stopped a simulation)",
    "message": "the solver's final message", "eps": "the ε of the stored states (1 when solved)",
    "collocation_json": "scheme, degree, intervals of the collocation polynomials",
    "cost": "J = Tr[M Σ(tf)] + ∫ (α/2 |u|² + Tr KΣ) dt", "terminal_cost": "Tr[M Σ(tf)]",
    "running_cost": "∫ (α/2 |u|² + Tr KΣ) dt", "control_energy": "∫ α/2 |u|² dt",
    "band_low": "lower end of the χ² band of the average NEES", "band_high": "upper end of that band",
    "runs": "Monte Carlo runs", "confidence": "confidence of the band", "time_step": "sampling period of the filter",
    "problem": "name of the replayed problem", "length_unit": "declared length unit", "time_unit": "declared time unit",
    "field_unit": "declared unit of the field", "C": "tracked level (NaN for reference motion)",
    "scenario": "scenario name", "seed": "random seed", "field": "the field", "formation": "formation kind",
    "motion": "motion of the centre", "gain": "control gain k (1/s)", "noise_std": "measurement noise σ",
    "snr": "signal-to-noise ratio", "projection": "metric of the constraint projection",
    "runtime_s": "wall time of the simulation (s)",
}  # fmt: skip


def _dataset_tables(path: Path) -> list[str]:
    import xarray as xr

    with xr.open_dataset(path, engine="h5netcdf") as ds:
        dims = ", ".join(f"`{k}` ({v} here)" for k, v in ds.sizes.items())
        lines = [f"Dimensions: {dims}.", "", "| variable | dimensions | meaning | units |", "|---|---|---|---|"]
        for kind, names in (("coordinate", list(ds.coords)), ("data", list(ds.data_vars))):
            for name in names:
                var = ds[name]
                role = " (coordinate)" if kind == "coordinate" else ""
                units = f"`{var.attrs['units']}`" if "units" in var.attrs else "— (names)"
                lines.append(f"| `{name}`{role} | {', '.join(var.dims)} | {_cell(var.attrs.get('long_name', ''))} | "
                             f"{units} |")  # fmt: skip
        lines += ["", "| global attribute | meaning |", "|---|---|"]
        lines += [f"| `{k}` | {_cell(ATTRIBUTES.get(k, ''))} |" for k in ds.attrs]
        lines.append("")
    return lines


def _summary_table(path: Path) -> list[str]:
    summary = json.loads(path.read_text(encoding="utf-8"))
    lines = ["| key | value in the example run |", "|---|---|"]
    for key, value in summary.items():
        text = json.dumps(value, ensure_ascii=False)
        lines.append(f"| `{key}` | {_cell(text if len(text) < 90 else text[:87] + '…')} |")
    return [*lines, ""]


def output_reference() -> str:
    """Markdown of every output file of every command, from the files of short example runs."""
    from mobisense.ocp.batch.sweep_runner import RESULT_COLUMNS
    from mobisense.ocp.plots import FIGURES

    lines = [
        "# Output files",
        "",
        "Every command writes into `--out DIR` (default `out/<input file name>`), each file atomically. The",
        "netCDF files follow CF-1.10: every variable and coordinate has `long_name` and `units` (UDUNITS strings",
        "in the units the input file declares), string labels (sensor names, `x`/`y`) are auxiliary coordinates",
        "`<dim>_label`, and the global attributes `Conventions`, `title`, `history` (time, command, version) and",
        "`source` say what wrote them. Read them back with `mobisense.core.open_dataset(path)` (labels restored",
        "as index coordinates) or any netCDF tool; `mobisense.Solution.load()` reads `solution.nc`.",
        "",
        "The tables below are generated from short runs of the shipped examples (so sizes are small).",
        "",
    ]
    with tempfile.TemporaryDirectory() as tmp:
        runs = _example_outputs(Path(tmp))
        for name, title, netcdf in (
            ("solve", "`mobisense solve`: `solution.nc`", "solution.nc"),
            ("replay_plan", "`mobisense replay` of a plan: `result.nc`", "result.nc"),
            ("replay_field", "`mobisense replay` on a field: `result.nc`", "result.nc"),
            ("leader_follower", "`mobisense simulate leader-follower`: `result.nc`", "result.nc"),
            ("distributed", "`mobisense simulate distributed`: `result.nc`", "result.nc"),
            ("steady_state", "`mobisense steady-state`: `trace_grid.nc`", "trace_grid.nc"),
        ):
            folder, command = runs[name]
            lines += [f"## {title}", "", f"Written by `{command}`.", "", *_dataset_tables(folder / netcdf),
                      f"### `summary.json` of `{command}`", "", *_summary_table(folder / "summary.json")]  # fmt: skip
    lines += [
        "With `--method both`, `solution.nc` also holds the indirect solution as `indirect_Sigma`, `indirect_p`,",
        "`indirect_v`, `indirect_u`, `indirect_Lam`, `indirect_lam_p`, `indirect_lam_v` on the axis `time_indirect`.",
        "",
        "Figures of `mobisense solve`: " + ", ".join(f"`{f}`" for f in FIGURES) + " (`continuation.png` when the",
        "indirect method ran: Tr Σ(tf) along the arclength continuation in ε, its folds circled).",
        "",
        "## `mobisense sweep`",
        "",
        "`results.parquet`: one row per task: `task` (problem hash), `index`, one column per varied key path (named",
        "as in the sweep file), then " + ", ".join(f"`{c}`" for c in RESULT_COLUMNS) + ".",
        "`tasks/part-NNNNNN.nc`: the solutions of the tasks finished between two flushes of the results (every",
        "64 tasks or 2 s), stacked: each variable of `solution.nc` above with a leading `task` dimension (the",
        "coordinate is the task's `index`; `task_id` its hash; an index coordinate that differs between the tasks,",
        "such as `time` when the horizon is varied, is `<name>_of_task`; each task's global attributes are the JSON",
        "string `task_attrs`). A row's `solution_file` names its file (relative to the sweep folder). Read one",
        "task with `mobisense.Solution.load(OUT / row.solution_file, task=row.index)`, or replay it with",
        "`solution: OUT/tasks/part-NNNNNN.nc` and `task: INDEX` in a plan replay. (Up to version 0.2.0 each task",
        "had its own `tasks/<index>_<task>/solution.nc`: one HDF5 file per task cost more than a warm solve.)",
        "`summary.json`: `mode`,",
        "`vary`, `counts` (tasks, solved, failed, error, resumed), `best` (task, index, cost, values), `warm_start`",
        "(median solve time and iterations, warm vs cold), `transcription_cache_hits`. `cost.png`: the optimal cost",
        "over the varied keys (a line for one key, a heat map for two).",
        "",
    ]
    return "\n".join(lines)


# ----------------------------------------------------------------------------------------- API
#: subpackage -> what it holds (page headings of the API reference)
PACKAGES = {
    "mobisense": "The public API",
    "mobisense.core": "Plumbing: configuration files, registries, units, netCDF, outputs",
    "mobisense.ocp": "The optimal-control problem and its solution",
    "mobisense.ocp.direct": "Direct collocation",
    "mobisense.ocp.indirect": "The indirect (PMP) method",
    "mobisense.ocp.batch": "Sweeps and multi-start",
    "mobisense.estimation": "Kalman filtering",
    "mobisense.estimation.fields": "Fields",
    "mobisense.estimation.cooperative": "Cooperative estimation and steady-state design",
    "mobisense.estimation.tracking": "Range sensing and the switching filter",
    "mobisense.estimation.distributed": "Distributed constrained filtering",
    "mobisense.formation": "Formation control and closed-loop simulations",
    "mobisense.formation.replay": "Replays",
    "mobisense.formation.leader_follower": "Leader–follower formations",
    "mobisense.formation.distributed": "Gradient formations and the distributed simulation",
}


def _modules(package: str) -> list[str]:
    folder = ROOT.joinpath(*package.split(".")[1:])
    return [f"{package}.{p.stem}" for p in sorted(folder.glob("*.py")) if p.stem != "__init__"]


def api_pages() -> dict[str, str]:
    """``api/<package>.md`` -> markdown with one mkdocstrings block per module of the package."""
    pages = {}
    for package, title in PACKAGES.items():
        lines = [f"# `{package}` — {title}", ""]
        if package == "mobisense":
            lines += ["::: mobisense", "    options:", "      members: false", ""]
            lines += [f"- [`{p}`]({p}.md) — {t}" for p, t in PACKAGES.items() if p != "mobisense"]
        for module in _modules(package):
            lines += [f"## `{module}`", "", f"::: {module}", "    options:", "      heading_level: 3",
                      "      show_root_heading: false", ""]  # fmt: skip
        pages[f"api/{package}.md"] = "\n".join(lines) + "\n"
    return pages
