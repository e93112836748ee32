"""`window_means`: the per-window training reading that race_scale_2m and race_scale_decline
share, and `lava_imitation.save_result`'s one-key updates."""

import json
import math

from studies.lib.common import window_means
from studies.lib.lava_imitation import save_result


def test_windows_are_half_open_and_skip_missing_values():
    steps = [100, 200, 250, 300, 400]
    values = [1.0, 0.0, math.nan, None, 0.5]
    # (0, 200]: 1.0 and 0.0; (200, 400]: NaN and None left out, 0.5; (400, 600]: nothing
    assert window_means(steps, values, 200, 600) == [0.5, 0.5, None]


def test_windows_stop_at_the_last_whole_window():
    assert window_means([10, 20, 30], [1.0, 2.0, 3.0], 10, 25) == [1.0, 2.0]


def test_save_result_keeps_the_other_keys(tmp_path):
    path = tmp_path / "results.json"
    save_result(path, "bco", 0.5)
    save_result(path, "soil", 0.25)
    save_result(path, "bco", 0.75)
    assert json.loads(path.read_text()) == {"bco": 0.75, "soil": 0.25}
    assert [p.name for p in tmp_path.iterdir()] == ["results.json"]  # no temp file left
