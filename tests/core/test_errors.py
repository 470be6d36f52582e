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
