"""The view service on loopback: it serves, says which scene it draws, and stops when asked."""

from __future__ import annotations

import logging
import math
import threading

import pytest

from services.view.config import ViewConfig
from services.view.service import ViewService
from shared.config import ConfigError


def test_the_view_says_which_scene_it_draws_and_stops(zenoh_hub, capsys, caplog) -> None:
    """The wire carries no scene: a view of another scene than the system's drew the cups where they are not,
    without a word (the demo and compose run pr2_two_cups_side, the view's default is pr2_two_cups). Its closing
    line names what it rejected, as every service's does (a review: the view's alone had no counts)."""
    caplog.set_level(logging.INFO, logger="foresight.view")
    service = ViewService(ViewConfig(port=0, scene="pr2_two_cups_side"), zenoh_hub())
    stop = threading.Event()
    thread = threading.Thread(target=service.run, args=(stop,), daemon=True)
    thread.start()
    out = ""
    try:
        for _ in range(400):
            out += capsys.readouterr().out
            if "watch live at" in out:
                break
            stop.wait(0.05)
    finally:
        stop.set()
        thread.join(30.0)
    assert not thread.is_alive()
    assert "watch live at ws://127.0.0.1:" in out and "drawing scene pr2_two_cups_side" in out, out
    assert "view: stopped; sent" in caplog.text and "; rejected none; CPU" in caplog.text, caplog.text


@pytest.mark.parametrize(("option", "value", "match"), [
    ("static_period_s", math.inf, r"view.static_period_s: must be 0.05..3600 s, got inf"),
    ("static_period_s", 1e-9, "view.static_period_s: must be 0.05..3600 s"),
    ("viz_rate_hz", math.inf, "view.viz_rate_hz: must be a finite number > 0, got inf"),
    ("viz_rate_hz", 0.0, "view.viz_rate_hz: must be a finite number > 0"),
])
def test_out_of_range_rates_and_periods_are_named(option, value, match) -> None:
    with pytest.raises(ConfigError, match=match):
        ViewConfig(**{option: value}).validate()
