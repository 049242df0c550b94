"""`is_whole_number`, the one check behind every "expected an integer" error of the configs."""

import math

import numpy as np
import pytest
from hypothesis import given, strategies as st

from paz6d.backend.checks import is_whole_number


@given(st.integers(-10**12, 10**12))
def test_integers_and_their_float_and_numpy_forms_are_whole(value):
    assert is_whole_number(value) and is_whole_number(float(value)) and is_whole_number(np.int64(value))


@given(st.floats(allow_nan=True, allow_infinity=True))
def test_a_float_is_whole_exactly_when_finite_with_no_fraction(value):
    assert is_whole_number(value) == (math.isfinite(value) and value == math.floor(value))


@pytest.mark.parametrize("value", [True, False, "3", None, [3], 2.5, np.float32(0.5), complex(3, 0)])
def test_booleans_strings_and_other_types_are_not(value):
    assert not is_whole_number(value)


@pytest.mark.parametrize("value", [True, "4", 2.5, 0, -1])
def test_the_generator_settings_refuse_what_is_not_a_positive_whole_number(value):
    from data_gen.config import _positive_int

    with pytest.raises(ValueError, match=r"width: expected a positive integer"):
        _positive_int(value, "width")
