"""Repeated warnings are rate limited, and the count of those suppressed is reported."""
import logging

from canest.apps.journal import RateLimit


def record(message, level=logging.WARNING, name="canest.bus"):
    return logging.LogRecord(name, level, __file__, 1, message, (), None)


def test_repeated_warning_passes_once_per_interval_and_reports_the_suppressed():
    now = [0.0]
    limit = RateLimit(interval=10.0, clock=lambda: now[0])
    assert limit.filter(record("input bus %s is down"))
    assert [limit.filter(record("input bus %s is down")) for _ in range(5)] == [False] * 5
    now[0] = 10.5
    later = record("input bus %s is down")
    assert limit.filter(later) and later.msg.endswith("(5 similar suppressed)")


def test_other_messages_and_info_are_not_limited():
    limit = RateLimit(interval=10.0, clock=lambda: 0.0)
    assert limit.filter(record("a"))
    assert limit.filter(record("b"))
    assert all(limit.filter(record("status", level=logging.INFO)) for _ in range(3))
