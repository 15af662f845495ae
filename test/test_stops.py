"""SIGINT at random moments (some during start-up) under 1 kHz traffic: every stop is clean.

A smaller run of the loop that `python -m rcbht_introspection.bench --only stops` makes 100/50
times: exit 0 within 5 s, no traceback or error line, statistics logged, bags readable. Two
stops of each kind; seed 28 makes one of each pair come during start-up and the other once up.
"""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from ros_support import require_ros

pytestmark = pytest.mark.ros


def test_every_stop_is_clean(tmp_path: Path) -> None:
    require_ros()
    from rcbht_introspection.bench.stops import stop_loop, summarise

    stops, sent = stop_loop(n_node=2, n_record=2, work=tmp_path, seed=28)
    summary = summarise(stops)
    assert sent["wrench_published"] > 1000
    assert [s.kind for s in stops].count("bag_record") == 2
    unclean = [s for s in stops if not s.clean]
    assert not unclean, json.dumps(summary, indent=1, default=str)
