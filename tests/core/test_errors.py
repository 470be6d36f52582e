"""One-line messages of numerical failures (:func:`mobisense.core.errors.numerical_failures`)."""

from __future__ import annotations

import numpy as np
import pytest

from mobisense.core.errors import ComputationError, ConfigError, numerical_failures


def test_a_singular_matrix_is_named_as_such_not_by_numpys_exception_type() -> None:
    with pytest.raises(ComputationError) as caught, numerical_failures("simulating x.yaml"):
        np.linalg.inv(np.array([[1.0, 2.0], [2.0, 4.0]]))  # rank 1: numpy raises LinAlgError("Singular matrix")
    text = str(caught.value)
    assert text.startswith("simulating x.yaml: linear algebra failed (Singular matrix): ")
    assert "LinAlgError" not in text and "\n" not in text


def test_a_casadi_error_keeps_its_last_sentence_without_the_cpp_stack() -> None:
    raw = (
        "Error in Function::call for 'F' [MXFunction] at .../casadi/core/function.cpp:1432:\n"
        ".../casadi/core/integrator.cpp:510: CVODES returned CV_TOO_MUCH_WORK\n"
        "the integration stopped at t = 3.5"
    )
    with pytest.raises(ComputationError, match=r"^solving x.yaml: the integration stopped at t = 3.5$"):
        with numerical_failures("solving x.yaml"):
            raise RuntimeError(raw)


def test_other_value_errors_keep_their_type_and_input_errors_pass_unchanged() -> None:
    with pytest.raises(ComputationError, match=r"^solving x.yaml: ValueError: bad shape$"):
        with numerical_failures("solving x.yaml"):
            raise ValueError("bad shape")
    with pytest.raises(ConfigError, match=r"^x.yaml: key: expected$"), numerical_failures("solving x.yaml"):
        raise ConfigError("x.yaml: key: expected")


def test_casadis_bare_evaluation_failure_is_explained() -> None:
    # red team: a field with Σ0 = 1e20·I ended in CasADi's bare message (exit 1), the text below verbatim
    raw = ".../casadi/core/function_internal.hpp:1766: Evaluation failed"
    with pytest.raises(ComputationError, match=r"^solving x.yaml: a CasADi function failed to evaluate \(") as caught:
        with numerical_failures("solving x.yaml"):
            raise RuntimeError(raw)
    assert ".hpp" not in str(caught.value) and "\n" not in str(caught.value)


def test_a_field_prior_far_above_the_fields_variance_is_refused_with_its_key() -> None:
    # red team: process.Sigma0 = 1e20·I on a 3 × 3 field of σ² = 1 ended in CasADi's "Evaluation failed" (exit 1)
    from short_runs import field_problem

    from mobisense.ocp.field import FIELD_PRIOR_RATIO
    from mobisense.ocp.problem import Problem

    data = field_problem(grid=(3, 3))
    data["process"]["Sigma0"] = (FIELD_PRIOR_RATIO * 1.01 * np.eye(9)).tolist()
    with pytest.raises(ConfigError, match=r"process\.Sigma0: expected variances at most 1e\+08 × the field's variance"):
        Problem.from_dict(data)
    data["process"]["Sigma0"] = (FIELD_PRIOR_RATIO * 0.99 * np.eye(9)).tolist()  # at the ceiling: accepted
    assert Problem.from_dict(data).matrices()["Sigma0"][0, 0] == FIELD_PRIOR_RATIO * 0.99
