"""The example files shipped with the package (``problems/*.yaml``, installed as package data).

``mobisense examples`` lists them with one line each and ``--copy DIR`` writes them out; every command
that reads a file also accepts a shipped example's name (``mobisense solve hussein2008``), resolved by
:func:`resolve_input` when no file of that name exists.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from importlib import resources
from pathlib import Path

__all__ = [
    "Example",
    "EXAMPLES",
    "examples_folder",
    "shipped_examples",
    "resolve_input",
    "example_hint",
    "copy_examples",
]


@dataclass(frozen=True)
class Example:
    """A shipped example: file name, the command that runs it, one line saying what it shows."""

    name: str
    command: str
    summary: str


#: every shipped example, in the order ``mobisense examples`` lists them
EXAMPLES: tuple[Example, ...] = (
    Example("hussein2008", "solve", "Hussein (2008)'s example: one sensor watches one scalar process (default)"),
    Example("hussein2008_paper", "solve", "the same solved as the paper did: indirect, ε steps, bvp4c defaults"),
    Example("coupled_two_sensor", "solve", "coupled correlated 2-state process, two sensors; one must stop at tf"),
    Example("terminal_and_bound", "solve", "the default example with a rendezvous at (2, -2) at rest and |u| <= 1.5"),
    Example("keep_out", "solve", "around an island disc and a polygonal reef, under a speed limit, in a workspace"),
    Example("separation", "solve", "two sensors converging on one process keep 1.5 L apart"),
    Example("replan_drift", "replay", "the default example re-planned every 0.5 T in a current, vs the open loop"),
    Example("field_mapping_5x5", "solve", "four gliders map a 5 × 5 correlated field (25 states, shooting)"),
    Example("field_mapping_10x10", "solve", "four gliders map a 10 × 10 correlated field (100 states, shooting)"),
    Example("field_mapping_island", "solve", "the 5 × 5 field around an island, in a workspace: path constraints"),
    Example("sweep_hussein2008", "sweep", "sweep of the default example over the control weight and the start"),
    Example("formation_cross", "steady-state", "cross formation: steady-state covariance minimised on a bound"),
    Example("formation_cross_equal_sides", "steady-state", "the cross formation with a = b imposed (a saddle)"),
    Example("formation_cross_interior", "steady-state", "cross formation whose optimum is an interior minimum"),
    Example("replay_hussein2008", "replay", "the default plan flown; its promised covariance checked by Monte Carlo"),
    Example("replay_two_charges", "replay", "two rotating platforms track a level curve of two charges' potential"),
    Example("replay_two_charges_fig3", "replay", "the rotating pair with strong short-range spatial noise"),
    Example("replay_isotherm13", "replay", "four platforms follow the 13 °C isotherm, formation shape adapted online"),
    Example("replay_isotherm13_adaptive", "replay", "the isotherm with a Hessian error that follows the estimate"),
    Example("replay_isotherm13_paper", "replay", "the isotherm with the paper's values (20 h, 1 km/h)"),
    Example("leader_follower_control1", "simulate leader-follower", "two unicycles under Control 1, exact sensing"),
    Example("leader_follower_control2", "simulate leader-follower", "Control 1 vs Control 2 from the same start"),
    Example("leader_follower_control3", "simulate leader-follower", "Controls 1-3, time-varying formation parameters"),
    Example("leader_follower_control3_paper", "simulate leader-follower", "Controls 1-3 with d0(0) = 1 m"),
    Example("leader_follower_five_agents", "simulate leader-follower", "five agents on the leader's path, two rules"),
    Example("leader_follower_khepera", "simulate leader-follower", "a follower seeing through 8 IR range sensors"),
    Example("leader_follower_khepera2", "simulate leader-follower", "the IR follower on a Khepera II sensor layout"),
    Example("leader_follower_khepera_switching", "simulate leader-follower", "the IR follower, β0 switched 0, π/6, 0"),
    Example("distributed_advection_diffusion", "simulate distributed", "12 sensors, 9 cells: PDE-constrained filter"),
    Example("distributed_advection_diffusion_paper", "simulate distributed", "the same with the paper's values"),
    Example("distributed_advection_diffusion_paper_consistent", "simulate distributed",
            "the paper's values, constrained by the PDE its field solves"),
)  # fmt: skip


def examples_folder() -> Path:
    """The folder of the shipped example files (``mobisense/problems`` in the installed package)."""
    return Path(str(resources.files("mobisense") / "problems"))


def shipped_examples() -> dict[str, Path]:
    """Example name -> its file, for every example listed in :data:`EXAMPLES`."""
    folder = examples_folder()
    return {example.name: folder / f"{example.name}.yaml" for example in EXAMPLES}


def resolve_input(path: str | Path) -> Path:
    """``path`` itself if it exists, else the shipped example of that name (``hussein2008[.yaml]``), else ``path``.

    Only a bare name (no folder) is looked up among the examples, so a missing ``dir/x.yaml`` is reported as
    missing rather than silently replaced. A missing ``x.yaml`` that is read as the example ``x`` is said at
    level INFO of the ``mobisense`` logger (the command line prints it as ``mobisense: note: …``).
    """
    if not isinstance(path, (str, os.PathLike)):
        raise TypeError(f"expected the path of a YAML file or the name of a shipped example, got {type(path).__name__}")
    path = Path(path)
    if path.exists() or path.parent != Path("."):
        return path
    shipped = shipped_examples().get(path.name.removesuffix(".yaml").removesuffix(".yml"))
    if shipped is None or not shipped.is_file():
        return path
    if path.suffix:  # a file name, not the bare name the examples are run by: say which file is read
        import logging

        logging.getLogger("mobisense").info("%s is not in %s: reading the shipped example %s", path,
                                            Path.cwd(), shipped)  # fmt: skip
    return shipped


#: entries of a folder looked at for a near-miss file name (a huge folder is not listed whole)
MAX_SIBLINGS = 2000


def example_hint(path: str | Path) -> str:
    """For a missing input file: a close file name beside it, or a shipped example's close name.

    ``"; did you mean dir/NAME.yaml?"`` comes first (the user's own, maybe edited, copy), else
    ``"; did you mean the shipped example 'NAME'? …"``.

    ``problems/hussein2008.yaml`` outside a clone, or a misspelled ``hussein2009``, point to the example that
    a bare name reads (:func:`resolve_input`); an empty string when no example's name is close.
    """
    import difflib
    import itertools

    path = Path(path)
    try:  # a near miss beside it first: the user's own (maybe edited) copy, not the shipped original
        entries = itertools.islice(path.parent.iterdir(), MAX_SIBLINGS)
        siblings = [p.name for p in entries if p.suffix in (".yaml", ".yml")]
    except OSError:
        siblings = []
    close = difflib.get_close_matches(path.name[:200], siblings, n=1, cutoff=0.8)
    if close:
        return f"; did you mean {path.parent / close[0]}?"
    stem = path.name.removesuffix(".yaml").removesuffix(".yml")
    close = difflib.get_close_matches(stem[:200], [e.name for e in EXAMPLES], n=1, cutoff=0.8)
    if not close:
        return ""
    return f"; did you mean the shipped example '{close[0]}'? (a bare name reads it; 'mobisense examples' lists them)"


def copy_examples(folder: str | Path, overwrite: bool = False) -> list[Path]:
    """Write every shipped example into ``folder`` (created if needed); return the files written.

    Files that already exist with the same content are left as they are (and not returned); files with other
    content are kept unless ``overwrite``. The references between examples (a sweep's ``base``, a replay's
    ``problem``) are relative, so the copies work as a set.

    Raises
    ------
    FileExistsError
        A file exists with other content and ``overwrite`` is false (nothing is written then).
    """
    from .files import atomic_path

    folder = Path(folder)
    sources = shipped_examples()
    there = {name: (folder / src.name).read_bytes() == src.read_bytes() for name, src in sources.items()
             if (folder / src.name).exists()}  # fmt: skip  (True: the same content)
    clashes = [folder / sources[name].name for name, same in there.items() if not same]
    if clashes and not overwrite:
        more = f" (and {len(clashes) - 1} more)" if len(clashes) > 1 else ""
        raise FileExistsError(f"{clashes[0]} exists with other content{more}")
    written = []
    for name, src in sources.items():
        if there.get(name):
            continue
        with atomic_path(folder / src.name) as tmp:
            tmp.write_bytes(src.read_bytes())
        written.append(folder / src.name)
    return written
