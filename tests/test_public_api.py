"""The public API: one installed namespace, lazy imports, a version, registries that users can extend."""

from __future__ import annotations

import json
import subprocess
import sys
import textwrap
from importlib.metadata import version
from pathlib import Path

import numpy as np
import pytest
import yaml
from reference_problems import PROBLEMS, hussein2008
from scipy.integrate import trapezoid

import mobisense
from mobisense import ConfigError, Problem, Solution, solve
from mobisense.ocp import BVP_SOLVERS
from mobisense.ocp.indirect import BVPSolver

HEAVY = ("casadi", "numpy", "scipy", "xarray", "matplotlib", "pydantic", "dask", "pyarrow", "pandas")


def _run(code: str, **env: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env={**env} or None)


def test_importing_the_package_loads_nothing_heavy():
    # the import-time target itself (--help < 0.3 s) is measured in benchmarks/bench_ocp_speed.py
    code = f"import sys, mobisense; print([m for m in {HEAVY!r} if m in sys.modules])"
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert result.stdout.strip() == "[]"


def test_version_matches_the_installed_distribution_and_the_command():
    assert mobisense.__version__ == version("mobisense")
    result = subprocess.run([sys.executable, "-m", "mobisense.cli", "--version"], capture_output=True, text=True)
    assert result.returncode == 0 and result.stdout.strip() == f"mobisense {mobisense.__version__}"


def test_unknown_public_name_is_an_attribute_error():
    with pytest.raises(AttributeError, match="no attribute 'not_a_name'"):
        mobisense.not_a_name  # noqa: B018


PATH_EXPECTED = "expected the path of a YAML file or the name of a shipped example"


@pytest.mark.parametrize(
    "call,message",
    [
        (lambda: solve({"process": {}}), "solve: problem: expected a Problem, a YAML path or an example's name, got a "
                                         "mapping"),
        (lambda: solve(None), "solve: problem: expected a Problem, a YAML path or an example's name, got NoneType"),
        (lambda: mobisense.load_problem(3), f"{PATH_EXPECTED}, got int"),
        (lambda: mobisense.load_scenario(["a"]), f"{PATH_EXPECTED}, got list"),
        (lambda: solve("hussein2008", init="previous.nc"), "solve: init: expected a Solution (of an earlier solve), "
                                                           "got str"),
    ],
    ids=["mapping", "None", "int", "list", "init"],
)  # fmt: skip
def test_arguments_of_the_wrong_type_are_named(call, message):
    # a programming error in a script: a TypeError that says which argument and what it takes, before any work
    with pytest.raises(TypeError) as raised:
        call()
    assert message in str(raised.value)


@pytest.mark.parametrize(
    "call,error,message",
    [
        (lambda: mobisense.multistart("no/such/problem.yaml", 1), ConfigError, "no/such/problem.yaml: file not found"),
        (lambda: mobisense.multistart({"process": {}}, 1), TypeError, "multistart: problem: expected a Problem, a "
                                                                      "YAML path or an example's name, got a mapping"),
        (lambda: mobisense.multistart("hussein2008", 2, workers=0), ConfigError, "multistart: workers: expected an "
                                                                                 "integer in 1 … 4096, got 0"),
        (lambda: mobisense.multistart("hussein2008", 0), ConfigError, "multistart: starts: expected an integer in 1 "
                                                                      "… 4096, got 0"),
        (lambda: solve("hussein2008", progress=5), TypeError, "solve: progress: expected a callable (called with "
                                                              "each HomotopyStep), got int"),
        (lambda: mobisense.sweep(PROBLEMS / "sweep_hussein2008.yaml", "unused", max_time=-1), ConfigError,
         "sweep: max_time: expected seconds in 1 … 1e8, got -1"),
        (lambda: mobisense.sweep(PROBLEMS / "sweep_hussein2008.yaml", "unused", max_memory=0), ConfigError,
         "sweep: max_memory: expected bytes in 1 MiB … 1 EiB, got 0"),
        (lambda: mobisense.sweep(PROBLEMS / "sweep_hussein2008.yaml", "unused", workers=0), ConfigError,
         "sweep: workers: expected an integer in 1 … 4096, got 0"),
    ],
    ids=["multistart-path", "multistart-mapping", "multistart-workers", "multistart-starts", "solve-progress",
         "sweep-max-time", "sweep-max-memory", "sweep-workers"],
)  # fmt: skip
def test_arguments_out_of_range_are_refused_before_any_work(call, error, message):
    # the rules of the command-line flags (--workers, --multistart, --max-time, --max-memory) and of solve's inputs
    with pytest.raises(error) as raised:
        call()
    assert message in str(raised.value)


def test_solve_direct_names_an_init_without_a_primal_dual_point():
    from mobisense.ocp.direct.solver import solve_direct

    problem = Problem.from_dict(hussein2008(collocation={"intervals": 10}))
    with pytest.raises(ValueError, match=r"solve_direct: init: expected a Solution or its nlp point \(a dict with "
                                         r"keys w, lam_w, lam_g, P, signature\), got a dict without w, "):
        solve_direct(problem, init={})  # fmt: skip
    with pytest.raises(TypeError, match="solve_direct: init: expected a Solution or its nlp point"):
        solve_direct(problem, init=[1.0])


@pytest.mark.parametrize("path", [PROBLEMS / "hussein2008.yaml", Path("/dev/zero")], ids=["yaml", "dev-zero"])
def test_open_dataset_names_a_file_that_is_not_netcdf(path):
    with pytest.raises(ConfigError, match=f"{path}: expected a netCDF file written by mobisense"):
        mobisense.open_dataset(path)


def _numpy_data(data):
    """``data`` with every list of numbers a numpy array, other lists tuples and numbers numpy scalars."""
    if isinstance(data, dict):
        return {key: _numpy_data(value) for key, value in data.items()}
    if isinstance(data, list):
        numeric = data and all(isinstance(v, (int, float, list)) and not isinstance(v, bool) for v in data)
        return np.array(data, dtype=float) if numeric else tuple(_numpy_data(v) for v in data)
    if isinstance(data, bool) or not isinstance(data, (int, float)):
        return data
    return np.int64(data) if isinstance(data, int) else np.float64(data)


def test_numpy_arrays_scalars_and_tuples_give_the_problem_lists_and_numbers_give():
    problem = Problem.from_dict(hussein2008())
    data = _numpy_data(problem.normalised())
    assert isinstance(data["process"]["Q"], np.ndarray) and isinstance(data["sensors"], tuple)
    from_numpy = Problem.from_dict(data)
    assert from_numpy == problem and from_numpy.digest() == problem.digest()
    assert Problem.from_dict(from_numpy.normalised()) == problem  # and round trips
    assert type(from_numpy.solver.collocation.intervals) is int
    data["process"]["Q"] = np.array([[np.nan]])  # non-finite values: refused as in a list
    with pytest.raises(ConfigError, match=r"process\.Q\[0\]\[0\]: expected a finite number, got nan"):
        Problem.from_dict(data)


@pytest.fixture(scope="module")
def solution() -> Solution:
    return solve(Problem.from_dict(hussein2008(collocation={"intervals": 40})))


def test_solution_repr_is_short_and_names_the_result(solution):
    text = repr(solution)
    assert len(text.splitlines()) <= 20 and len(text) < 2000
    assert "hussein2008" in text and "solved" in text and f"{solution.cost:.10g}" in text


def test_sample_reproduces_the_nodes_and_the_polynomials(solution):
    # at the state nodes the collocation polynomials interpolate the NLP's values exactly (to rounding)
    at_nodes = solution.sample(solution.t)
    np.testing.assert_allclose(at_nodes.Sigma, solution.Sigma, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(at_nodes.p, solution.p, rtol=0, atol=1e-11)
    controls = solution.sample(solution.t_u)
    np.testing.assert_allclose(controls.u, solution.u, rtol=0, atol=1e-9 * np.abs(solution.u).max())
    # between the nodes, the sensor position of a double integrator is the integral of the sampled
    # velocity: trapezoid on a 20x finer grid of the polynomials, error O(h_fine^2) ≈ 1e-6 of the range
    t = np.linspace(solution.t[0], solution.t[-1], 4001)
    s = solution.sample(t)
    integrated = s.p[0] + trapezoid(s.v, t, axis=0)
    np.testing.assert_allclose(integrated, s.p[-1], rtol=0, atol=1e-5 * np.abs(solution.p).max())
    with pytest.raises(ValueError, match="expected times in"):
        solution.sample([solution.t[-1] + 1.0])


@pytest.mark.parametrize(
    "t,error,message",
    [
        (np.nan, ValueError, "t: expected finite times, got nan"),
        ([0.0, np.inf], ValueError, "t: expected finite times, got inf"),
        ("0", TypeError, "t: expected a time or a 1-D array of times (numbers), got '0'"),
        (np.zeros((2, 2)), ValueError, "t: expected a time or a 1-D array of times, got an array of shape (2, 2)"),
    ],
    ids=["nan", "inf", "string", "2-D"],
)
def test_sample_refuses_times_that_are_not_a_vector_of_finite_numbers(solution, t, error, message):
    with pytest.raises(error) as raised:
        solution.sample(t)
    assert message in str(raised.value)


def test_solution_round_trips_through_netcdf_with_its_polynomials(solution, tmp_path):
    solution.save(tmp_path)
    loaded = Solution.load(tmp_path)
    assert loaded.collocation == solution.collocation and loaded.status is solution.status
    t = np.linspace(0.0, 10.0, 37)
    np.testing.assert_allclose(loaded.sample(t).Sigma, solution.sample(t).Sigma, rtol=1e-14)
    assert json.loads((tmp_path / "summary.json").read_text())["status"] == "solved"


@pytest.mark.slow
def test_a_previous_solution_warm_starts_the_next_solve(solution):
    data = hussein2008(collocation={"intervals": 40})
    data["cost"]["alpha"] = 0.006
    heavier = Problem.from_dict(data)
    warm = solve(heavier, init=solution)
    cold = solve(heavier)
    assert warm.stats["start"] == "warm start from init"
    assert abs(warm.cost - cold.cost) <= 1e-8 * cold.cost  # same optimum (Ipopt tol 1e-9)
    assert sum(s.iterations for s in warm.homotopy) < sum(s.iterations for s in cold.homotopy)


def test_a_registered_bvp_solver_can_be_chosen_in_a_problem_file():
    class Mine(BVP_SOLVERS["scipy"]):  # type: ignore[misc, valid-type]
        name = "mine"

    assert issubclass(Mine, BVPSolver)
    data = hussein2008()
    data.setdefault("solver", {})["bvp"] = {"solver": "mine"}
    with pytest.raises(mobisense.ConfigError, match="unknown BVP solver 'mine'"):
        Problem.from_dict(data)
    BVP_SOLVERS.register("mine", Mine)
    try:
        assert Problem.from_dict(data).solver.bvp.solver == "mine"
    finally:
        BVP_SOLVERS._entries.pop("mine")


@pytest.mark.slow
def test_an_installed_package_adds_a_noise_model_through_its_entry_point(tmp_path):
    (tmp_path / "linear_range_noise.py").write_text(
        textwrap.dedent(
            '''
            from typing import ClassVar, Literal

            import casadi as ca

            from mobisense.core.config import PositiveFloat
            from mobisense.ocp.noise_models import NoiseModel


            class LinearRange(NoiseModel):
                model: Literal["linear_range"] = "linear_range"
                sigma0: PositiveFloat
                length: PositiveFloat
                n_parameters: ClassVar[int] = 2

                def parameters(self):
                    return [self.sigma0, self.length]

                @staticmethod
                def variance(p, s, theta):
                    return theta[0] * ca.sqrt(1 + ca.sumsqr(p - s) / theta[1] ** 2)
            '''
        )
    )
    info = tmp_path / "linear_range_noise-1.0.dist-info"
    info.mkdir()
    (info / "METADATA").write_text("Metadata-Version: 2.1\nName: linear-range-noise\nVersion: 1.0\n")
    (info / "entry_points.txt").write_text("[mobisense.noise_models]\nlinear_range = linear_range_noise:LinearRange\n")
    data = hussein2008(collocation={"intervals": 20})
    data["sensors"][0]["noise"] = {"model": "linear_range", "sigma0": 3.0, "length": 2.0}
    problem_file = tmp_path / "problem.yaml"
    problem_file.write_text(yaml.safe_dump(data))
    env = {"PYTHONPATH": str(tmp_path), "PATH": str(Path(sys.executable).parent)}
    run = subprocess.run(
        [sys.executable, "-m", "mobisense.cli", "solve", str(problem_file), "--out", str(tmp_path / "out"),
         "--no-plot", "--quiet"],
        capture_output=True, text=True, env=env,
    )  # fmt: skip
    assert run.returncode == 0, run.stderr
    summary = json.loads((tmp_path / "out" / "summary.json").read_text())
    assert summary["status"] == "solved" and summary["cost"] < summary["baseline"]["cost"]
