"""Terminal display of a solve: a live progress bar over homotopy steps and a short result table (rich)."""

from __future__ import annotations

import sys
from pathlib import Path
from typing import TYPE_CHECKING

from .homotopy import fixed_schedule
from .problem import Problem
from .solution import HomotopyStep, Solution
from .solving import solve

if TYPE_CHECKING:
    from rich.table import Table

    from .direct.iteration_limit import IpoptIteration

__all__ = ["SolveReporter"]


class SolveReporter:
    """Runs a solve with progress on stderr and prints the result table on stdout (rich, not loaded if quiet)."""

    def __init__(self, problem: Problem, quiet: bool = False) -> None:
        self.problem = problem
        self.quiet = quiet

    def run(self, method: str) -> Solution:
        """Solve with ``method``, updating a progress bar after each ε step and each iteration of a long Ipopt call."""
        if self.quiet:
            return solve(self.problem, method)
        from rich.console import Console
        from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn

        from .direct.iteration_limit import watch_iterations

        h = self.problem.solver.homotopy
        total = 1 if h.mode == "none" else (len(fixed_schedule(h.step)) if h.mode == "fixed" else None)
        if method == "shooting":  # the coarse ε steps and the fine ε = 1 solve
            total = len(self.problem.solver.shooting.homotopy) + 1
        if total is not None and method == "both":
            total *= 2  # the direct, then the indirect continuation
        with Progress(
            TextColumn("[bold]{task.description}"),
            BarColumn(),
            TextColumn("{task.fields[info]}"),
            TimeElapsedColumn(),
            console=Console(stderr=True, highlight=False),
            transient=not sys.stderr.isatty(),
        ) as progress:
            task = progress.add_task(f"{self.problem.name} ({method})", total=total, info="building…")

            def on_step(step: HomotopyStep) -> None:
                mark = "✓" if step.success else "✗"
                progress.update(
                    task,
                    advance=1 if step.success else 0,
                    info=f"ε = {step.eps:.3g}  J_ε = {step.cost:.6g}  {step.iterations} it {mark}",
                )

            def on_iteration(it: IpoptIteration) -> None:  # a long Ipopt call (large NLPs, fields)
                # Ipopt's own names: the objective (J over its scale) and inf_pr (largest constraint violation)
                progress.update(task, info=f"Ipopt iteration {it.iteration}: objective {it.objective:.5g}, "
                                f"inf_pr {it.violation:.1e}")  # fmt: skip

            with watch_iterations(on_iteration):
                return solve(self.problem, method, progress=on_step)

    def report(self, solution: Solution, out: Path) -> None:
        """Print the cost split, homotopy summary and timings."""
        if self.quiet:
            return
        from rich.console import Console
        from rich.table import Table

        s = solution.summary()
        steps = solution.homotopy
        table = Table(
            title=f"{solution.problem.name} — {solution.method} method — {solution.status.value}", show_header=False
        )
        table.add_column("quantity")
        table.add_column("value", justify="left")
        solved = solution.success
        # a failed solve holds the plan of the last ε it solved; its J is the true cost (ε = 1 weights) of that plan
        label = "J (ε = 1)" if solved else f"J of the plan held (ε = {solution.eps:g})"
        table.add_row(label, f"{s['cost']:.10g}")
        table.add_row("  terminal Tr[MΣ(tf)]", f"{s['terminal_cost']:.10g}")
        table.add_row("  running ∫(α/2|u|² + Tr KΣ)", f"{s['running_cost']:.6g}")
        table.add_row("  control energy ∫α/2|u|²", f"{s['control_energy']:.6g}")
        check = s.get("plan_check")
        if check and check.get("cost") is not None:  # the controls integrated independently of the collocation
            table.add_row("  J of the plan re-integrated", f"{check['cost']:.10g} (J differs by "
                          f"{check['relative_difference']:.1e})")  # fmt: skip
        base = solution.baseline.get("cost")
        if base is not None:
            table.add_row("no-control baseline J (u ≡ 0)", f"{base:.10g}")
            if not solved:
                table.add_row("improvement over the baseline", "none quoted: the solve did not reach ε = 1")
            elif s["baseline_feasible"]:
                table.add_row("improvement over the baseline", f"{s['improvement_percent']:.2f} %")
            else:
                table.add_row("improvement over the baseline", "none quoted: the baseline is infeasible")
                for violation in s["baseline_violations"]:
                    table.add_row("  baseline violates", violation)
        if steps and solution.method != "indirect":  # the indirect rows below tell its continuation
            strategy = solution.stats.get("strategy") or {}
            starts = strategy.get("starts") or []
            if len(starts) > 1:  # several starts (solver.strategy): their steps together
                reached = sum(start.get("eps_reached") == 1.0 for start in starts)
                table.add_row("starts tried", f"{len(starts)}, {reached} reached ε = 1 ({strategy.get('kept')} kept)")
                table.add_row("  Ipopt solves of all starts", f"{len(steps)} (ε steps; ε reached {solution.eps:g})")
            else:
                table.add_row("Ipopt solves", f"{len(steps)} (ε steps; ε reached {solution.eps:g})")
            iterations = sum(x.iterations for x in steps)
            table.add_row("  Ipopt iterations", f"{iterations} (first step {steps[0].iterations})")
            table.add_row("  time of the ε steps", f"{s['solve_time_s']:.3f} s (first step {steps[0].time_s:.3f} s)")
        if "build_time_s" in s:
            table.add_row("transcription build", f"{s['build_time_s']:.3f} s")
        table.add_row("smallest eigenvalue of Σ(t)", f"{s['min_sigma_eigenvalue']:.4g}")
        self._indirect_rows(table, s)
        multistart = s.get("multistart")
        if multistart:
            costs = ", ".join(f"{g['cost']:.8g} (×{len(g['starts'])})" for g in multistart["optima"])
            table.add_row(
                "multi-start",
                f"{multistart['converged']}/{multistart['starts']} converged; "
                f"{_count(len(multistart['optima']), 'distinct optimum', 'distinct optima')}: {costs}",
            )
        table.add_row("output", str(out))
        Console(stderr=False, highlight=False).print(table)

    @staticmethod
    def _continuation_rows(table: Table, indirect: dict) -> None:
        """The indirect solve: result, and one account of its ε steps, arclength steps and time."""
        records = indirect["homotopy"]
        steps = [r for r in records if r.get("eps", 0.0) > 0.0]
        start = sum(r["time_s"] for r in records if r.get("eps", 0.0) == 0.0)
        stepping = sum(r["time_s"] for r in steps)
        polish = (indirect.get("polish") or {}).get("time_s", 0.0)
        total = indirect["time_s"]
        polished = f", polished by solve_bvp on {indirect['polish']['nodes']} nodes" if polish else ""
        table.add_row(
            "indirect (PMP BVP)",
            f"J = {indirect['cost']:.10g}, {indirect['status']}; {indirect['solver']} BVP solver{polished}",
        )
        if not steps:
            table.add_row("  time", f"{total:.3f} s")
            return
        folds = ("folds at ε = " + ", ".join(f"{f:.3g}" for f in indirect["folds"])) if indirect["folds"] else "no fold"
        rejected = sum(r.get("rejected_steps", 0) for r in steps)
        table.add_row(
            "  continuation in ε",
            f"{_count(len(steps), 'ε step')} taken as {_count(indirect['arclength_steps'], 'arclength step')} "
            f"({rejected} rejected); "
            f"{indirect['newton_iterations']} Newton iterations; {folds}",
        )
        table.add_row(
            "  time",
            f"{total:.3f} s in all: ε steps {stepping:.3f} s, Kalman (ε = 0) BVP {start:.3f} s"
            + (f", polish {polish:.3f} s" if polish else "")
            + f", set-up {max(total - stepping - start - polish, 0.0):.3f} s",
        )

    @staticmethod
    def _indirect_rows(table: Table, s: dict) -> None:
        """Rows of the indirect continuation, the direct-seeded refinement and the agreement (if present)."""
        indirect = s.get("indirect")
        if indirect:
            SolveReporter._continuation_rows(table, indirect)
        seeded = s.get("seeded")
        if seeded:
            table.add_row(
                "direct-seeded BVP",
                f"J = {seeded['cost']:.10g}, {seeded['status']}, {seeded['time_s']:.3f} s, "
                f"{seeded['nodes']} nodes ({seeded['solver']})",
            )
        agreement = s.get("agreement")
        if agreement:
            table.add_row("agreement: cost (relative)", f"{agreement['cost_rel_diff']:.2e}")
            table.add_row(
                "  max state / control / costate",
                f"{agreement['max_state_diff']:.2e} / {agreement['max_control_diff']:.2e} / "
                f"{agreement['max_costate_diff']:.2e}",
            )
        for method, residuals in (s.get("optimality") or {}).items():
            if residuals:
                table.add_row(
                    f"  {method}: |∂H/∂u|, transversality, ΔH",
                    f"{residuals['dH_du']:.1e}, {residuals['transversality']:.1e}, "
                    f"{residuals['hamiltonian_variation']:.1e}",
                )


def _count(number: int, singular: str, plural: str | None = None) -> str:
    """``"1 ε step"``, ``"3 ε steps"`` (``plural`` when it is not ``singular + "s"``)."""
    return f"{number} {singular if number == 1 else plural or singular + 's'}"
