"""Field-scale sensor planning: the scaling table of the shooting method against the issue's targets.

For square grids n = g × g (default g = 2, 3, 4, 5, 7, 10) with N = 4 gliders and tf = 20 (the settings
of problems/field_mapping_5x5.yaml), each solve runs as its own ``mobisense solve`` process under
``/usr/bin/time -v`` (whole process: import, build, homotopy, outputs without figures), and the direct
collocation (K = 100, the same problem with ``--method direct``) beside it for the grids in
``--collocation`` under a wall-clock cap and an address-space cap. Prints wall and CPU time, peak RSS,
Ipopt iterations and J, the fitted growth exponent of the shooting time in n, and PASS/MISS against the
targets: n = 25 in < 60 s, n = 100 in < 10 min and < 4 GB, growth exponent ≤ 3.

Usage: ``python benchmarks/bench_field.py [--grids 2,3,4,5,7,10] [--collocation 2] [--cap 600] [--mem-gb 8]``
"""

from __future__ import annotations

import argparse
import json
import os
import re
import signal
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np
import yaml
from rich.console import Console
from rich.table import Table

from mobisense.core.examples import resolve_input

console = Console(width=150)


def problem_file(folder: Path, g: int) -> Path:
    """field_mapping_5x5.yaml with a g × g grid."""
    data = yaml.safe_load(resolve_input(Path("field_mapping_5x5")).read_text(encoding="utf-8"))
    data["name"] = f"field_mapping_{g}x{g}"
    data["process"]["field"]["grid"] = [g, g]
    path = folder / f"{data['name']}.yaml"
    path.write_text(yaml.safe_dump(data), encoding="utf-8")
    return path


def run(path: Path, method: str, out: Path, cap: float, mem_gb: float) -> dict:
    """One solve in its own process; wall, CPU, peak RSS from ``/usr/bin/time -v``; J from summary.json."""
    limit = int(mem_gb * 1024**3)
    exe = str(Path(sys.executable).parent / "mobisense")
    cmd = ["/usr/bin/time", "-v", exe, "solve", str(path), "--method", method,
           "--out", str(out), "--quiet", "--no-plot"]  # fmt: skip

    def cap_memory() -> None:
        import resource

        resource.setrlimit(resource.RLIMIT_AS, (limit, limit))

    # its own session, so that a timeout ends the solver too, not only /usr/bin/time
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            preexec_fn=cap_memory, start_new_session=True)  # fmt: skip
    try:
        _, err = proc.communicate(timeout=cap)
    except subprocess.TimeoutExpired:
        os.killpg(proc.pid, signal.SIGKILL)
        proc.communicate()
        return {"status": f"timeout ({cap:g} s)", "wall": cap}

    def field(name: str) -> float:
        match = re.search(rf"{name}: ([0-9.:]+)", err)
        return float("nan") if match is None else _seconds(match.group(1))

    row = {"wall": field("Elapsed \\(wall clock\\) time \\(h:mm:ss or m:ss\\)"),
           "cpu": field("User time \\(seconds\\)") + field("System time \\(seconds\\)"),
           "rss_mb": field("Maximum resident set size \\(kbytes\\)") / 1024, "code": proc.returncode}  # fmt: skip
    summary = out / "summary.json"
    if proc.returncode == 0 and summary.exists():
        s = json.loads(summary.read_text())
        row.update(status=s["status"], J=s["cost"], J0=s["baseline"]["cost"],
                   iterations=sum(h["iterations"] for h in s["homotopy"]))  # fmt: skip
    else:
        last = [line for line in err.splitlines() if line.strip() and not line.startswith("\t")]
        row["status"] = f"exit {proc.returncode}: {(last[-1] if last else '')[:60]}"
    return row


def _seconds(text: str) -> float:
    parts = [float(p) for p in text.split(":")]
    return sum(p * 60**i for i, p in enumerate(reversed(parts)))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--grids", default="2,3,4,5,7,10")
    parser.add_argument("--collocation", default="2", help="grids also solved by the direct collocation")
    parser.add_argument("--cap", type=float, default=600.0, help="wall-clock cap per solve (s)")
    parser.add_argument("--mem-gb", type=float, default=8.0, help="address-space cap per solve (GB)")
    args = parser.parse_args()
    grids = [int(g) for g in args.grids.split(",")]
    colloc = [int(g) for g in args.collocation.split(",") if g]
    console.print(f"load average before: {os.getloadavg()[0]:.1f} (2-core machine)")
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        for g in grids:
            path = problem_file(folder, g)
            for method in ["shooting"] + (["direct"] if g in colloc else []):
                row = run(path, method, folder / f"{g}_{method}", args.cap, args.mem_gb)
                row.update(n=g * g, method=method, load=os.getloadavg()[0])
                rows.append(row)
                console.print(row)
    table = Table(title="field mapping, N = 4, tf = 20 (each solve its own process)")
    for col in ("n", "method", "wall s", "CPU s", "peak RSS MB", "iterations", "J", "no-control J", "status", "load"):
        table.add_column(col)
    for r in rows:
        table.add_row(str(r["n"]), r["method"], f"{r['wall']:.1f}", f"{r.get('cpu', float('nan')):.1f}",
                      f"{r.get('rss_mb', float('nan')):.0f}", str(r.get("iterations", "—")),
                      f"{r['J']:.8f}" if "J" in r else "—", f"{r['J0']:.6f}" if "J0" in r else "—",
                      r["status"], f"{r['load']:.1f}")  # fmt: skip
    console.print(table)
    shoot = {r["n"]: r for r in rows if r["method"] == "shooting" and r["status"] == "solved"}
    ns = np.array(sorted(shoot))
    if len(ns) >= 2:
        k_wall = np.polyfit(np.log(ns), np.log([shoot[n]["wall"] for n in ns]), 1)[0]
        k_cpu = np.polyfit(np.log(ns), np.log([shoot[n]["cpu"] for n in ns]), 1)[0]
        big = ns[ns >= 25]
        k_big = np.polyfit(np.log(big), np.log([shoot[n]["cpu"] for n in big]), 1)[0] if len(big) >= 2 else np.nan
        console.print(f"growth exponent of the shooting time in n: {k_wall:.2f} (wall), {k_cpu:.2f} (CPU) over "
                      f"n = {ns.min()}…{ns.max()}; {k_big:.2f} (CPU) over n ≥ 25")  # fmt: skip
        console.print(f"{'PASS' if max(k_wall, k_cpu) <= 3 else 'MISS'}  growth exponent ≤ 3")
    for n, limit, mem in ((25, 60.0, None), (100, 600.0, 4096.0)):
        if n in shoot:
            ok = shoot[n]["wall"] < limit and (mem is None or shoot[n]["rss_mb"] < mem)
            extra = "" if mem is None else f" and {shoot[n]['rss_mb']:.0f} MB < 4 GB"
            console.print(f"{'PASS' if ok else 'MISS'}  n = {n}: {shoot[n]['wall']:.1f} s < {limit:g} s{extra}")
        elif n in {g * g for g in grids}:
            console.print(f"MISS  n = {n}: not solved")


if __name__ == "__main__":
    main()
