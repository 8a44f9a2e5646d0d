"""HumanPublisher: poses and markers each on its key, counted, over real Zenoh on loopback."""

from __future__ import annotations

import threading
import time

import numpy as np

from shared.human_source import HumanPublisher
from shared.protocol import DemoMarker, HumanPose, Keys
from shared.transport import open_session, subscribe_ordered


def test_poses_and_markers_go_to_their_keys_and_are_counted(zenoh_hub) -> None:
    a, b = zenoh_hub(), zenoh_hub()
    keys = Keys("hs")
    got: list = []
    lock = threading.Lock()

    def add(msg) -> None:
        with lock:
            got.append(msg)

    start = DemoMarker(stamp=1.0, tick=-1, demo_id=0, event="start", true_class=-1, class_name="live", n_samples=0)
    pose = HumanPose(stamp=1.0, tick=-1, tick_last=True, demo_id=0, index=0, features=np.zeros(12))
    end = DemoMarker(stamp=1.1, tick=-1, demo_id=0, event="end", true_class=-1, class_name="live", n_samples=1)
    with open_session(a) as sa, open_session(b) as sb:
        subscribe_ordered(sa, keys.human_all, {keys.pose: HumanPose, keys.demo: DemoMarker}, add)
        human = HumanPublisher(sb, keys)
        deadline = time.monotonic() + 10.0
        while not human.matched() and time.monotonic() < deadline:
            time.sleep(0.02)
        for m in (start, pose, end):
            human.put(m)
        deadline = time.monotonic() + 10.0
        while len(got) < 3 and time.monotonic() < deadline:
            time.sleep(0.02)
    assert [type(m).__name__ for m in got] == ["DemoMarker", "HumanPose", "DemoMarker"]
    assert (human.poses, human.markers, human.starts) == (1, 2, 1)
