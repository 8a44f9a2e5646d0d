"""The view service on loopback: it serves, says which scene it draws, and stops when asked."""

from __future__ import annotations

import logging
import math
import threading
import time

import pytest

from services.view.config import ViewConfig
from services.view.service import ViewService
from shared.config import ConfigError
from shared.protocol import DemoMarker, HumanPose, Message
from shared.synthetic import generate_library
from shared.transport import TypedPublisher, open_session


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
    assert "view: stopped; sent" in caplog.text, caplog.text
    assert "; rejected none; no drawing failed; CPU" in caplog.text, caplog.text


@pytest.mark.parametrize(("option", "value", "match"), [
    ("static_period_s", math.inf, r"view.static_period_s: must be 0.05..3600 s, got inf"),
    ("static_period_s", 1e-9, "view.static_period_s: must be 0.05..3600 s"),
    ("viz_rate_hz", math.inf, "view.viz_rate_hz: must be a finite number > 0, got inf"),
    ("viz_rate_hz", 0.0, "view.viz_rate_hz: must be a finite number > 0"),
])
def test_out_of_range_rates_and_periods_are_named(option, value, match) -> None:
    with pytest.raises(ConfigError, match=match):
        ViewConfig(**{option: value}).validate()


def test_a_reachs_end_marker_is_drawn_after_its_last_pose(zenoh_hub, wait_until) -> None:
    """Poses and markers came on two subscriptions (two Zenoh threads): the end marker of a reach was drawn before
    its last pose in 38 of 40 reaches, and the body was left drawn as still reaching (blue, not 'ended')."""
    service = ViewService(ViewConfig(port=0, scene="pr2_two_cups_side"), zenoh_hub())
    seen: list[tuple[str, int, int | str]] = []
    draw = service.core.on_message

    def record(msg: Message, watched=None):  # noqa: ANN001, ANN202 - the core's own signature
        seen.append((msg.TYPE, msg.demo_id, msg.index if isinstance(msg, HumanPose) else msg.event))
        return draw(msg, watched)

    service.core.on_message = record  # type: ignore[method-assign]
    demo = generate_library(n_classes=2, n_demos=1, seed=0).demos[0]
    stop = threading.Event()
    thread = threading.Thread(target=service.run, args=(stop,), daemon=True)
    thread.start()
    sent: list[tuple[str, int, int | str]] = []
    try:
        assert wait_until(lambda: service.server is not None, 15.0)
        with open_session(zenoh_hub()) as session:
            keys = service.keys
            poses, markers = TypedPublisher(session, keys.pose, block=True), TypedPublisher(session, keys.demo,
                                                                                          block=True)
            time.sleep(0.5)  # the subscriptions reach the publisher
            for reach in range(1, 11):
                def mark(event: str, reach: int = reach) -> None:
                    markers.put(DemoMarker(stamp=time.time(), tick=-1, demo_id=reach, event=event, true_class=0,
                                           class_name=demo.class_name, n_samples=5))
                    sent.append(("DemoMarker", reach, event))

                mark("start")
                for i in range(5):
                    poses.put(HumanPose(stamp=time.time(), tick=-1, tick_last=True, demo_id=reach, index=i,
                                        features=demo.features[i]))
                    sent.append(("HumanPose", reach, i))
                mark("end")  # right after the last pose, as the replayer and the tracker send it
            assert wait_until(lambda: len(seen) >= len(sent), 15.0), f"{len(seen)} of {len(sent)} drawn"
    finally:
        stop.set()
        thread.join(30.0)
    assert not thread.is_alive()
    assert seen == sent
