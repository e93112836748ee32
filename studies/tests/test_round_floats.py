"""A run's plotted curve is stored to 6 significant digits; what a table reads is untouched."""

import math

from studies.lib.common import round_floats


def test_round_floats_keeps_whole_numbers_and_non_finite_values():
    curve = [[1024.0, 0.123456789, math.nan, 0], [2048.0, -25.8015104871345, math.inf, 3]]
    out = round_floats(curve)
    assert out[0][0] == 1024.0 and out[1][3] == 3
    assert out[0][1] == 0.123457 and out[1][1] == -25.8015
    assert math.isnan(out[0][2]) and out[1][2] == math.inf
    assert round_floats({"a": (1234567.0, 0.5)}) == {"a": [1234567.0, 0.5]}
