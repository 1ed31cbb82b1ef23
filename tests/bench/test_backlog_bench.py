"""tests/bench/backlog.py's own logic: the backlogs it draws."""
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
import backlog  # noqa: E402


def test_backlogs_drawn_apart_inside_the_run():
    """Holds in HOLD_S, none in the first 2 s or the last second, none inside another (the
    simulator refuses overlapping ones), some within AGAIN_S of the last one's end (stalled
    again while draining), and the same for the same seed."""
    again = 0
    for seed in range(1, 21):
        b = backlog.draw_backlogs(seed, 120.0, 0.3)
        assert b == backlog.draw_backlogs(seed, 120.0, 0.3)
        assert len(b) > 10
        for (s0, h0), (s1, _) in zip(b, b[1:]):
            assert s1 > s0 + h0
            again += s1 - (s0 + h0) <= backlog.AGAIN_S
        assert all(2.0 <= s < 119.0 and backlog.HOLD_S[0] <= h <= backlog.HOLD_S[1] for s, h in b)
    assert again > 20
    assert backlog.draw_backlogs(1, 120.0, 0.3) != backlog.draw_backlogs(2, 120.0, 0.3)
