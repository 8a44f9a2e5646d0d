"""A recorded person's keypoints through the tracker into the real predictor, under mutual TLS and access control.

`foresight tracker --from FILE` plays a keypoint recording as the ``sensor`` role, the tracker (role ``tracker``)
publishes the human's poses and reach markers, and the predictor (role ``predictor``), unchanged, recognises the
reach and predicts its occupancy. The test's session is the router.
"""

from __future__ import annotations

import dataclasses
import threading
from pathlib import Path

import numpy as np

from services.experiments.harness import ServiceThread
from services.predictor.core import PredictorConfig
from services.predictor.service import PredictorService
from services.processes import free_port
from services.tracker.config import TrackerServiceConfig
from services.tracker.service import TrackerService
from shared.config import ZenohConfig
from shared.keypoints.library import write_keypoint_library
from shared.library import load_library
from shared.protocol import AT_REST, ClassPosterior, DemoMarker, HumanPose, Keys, OccupancyGrid
from shared.security.acl import ROLES
from shared.security.certificates import init_security_dir
from shared.transport import Presence, open_session, subscribe, subscribe_ordered


def test_a_recorded_person_through_the_tracker_is_recognised_by_the_predictor(system_files, tmp_path: Path) -> None:
    security = tmp_path / "security"
    init_security_dir(security, ROLES)
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    hub = ZenohConfig(mode="peer", listen=[endpoint], connect=[], multicast_scouting=False, role="router",
                      security_dir=str(security))
    base = ZenohConfig(mode="peer", listen=["tcp/127.0.0.1:0"], connect=[endpoint], multicast_scouting=False,
                       security_dir=str(security))
    human = load_library(system_files.human)
    write_keypoint_library(human, tmp_path / "keypoints")
    recording = tmp_path / "keypoints" / f"{system_files.human_class}.csv"
    keys = Keys(hub.prefix)
    posteriors: list[ClassPosterior] = []
    grids: list[OccupancyGrid] = []
    human_msgs: list = []
    lock = threading.Lock()

    def keep(into: list):
        def add(msg) -> None:
            with lock:
                into.append(msg)
        return add

    with open_session(hub) as session:
        subs = [subscribe(session, keys.posterior, ClassPosterior, keep(posteriors)),
                subscribe(session, keys.occupancy, OccupancyGrid, keep(grids)),
                subscribe_ordered(session, keys.human_all, {keys.pose: HumanPose, keys.demo: DemoMarker},
                                  keep(human_msgs))]
        predictor = ServiceThread("predictor", PredictorService(
            PredictorConfig(model=system_files.model), dataclasses.replace(base, role="predictor")).run).start()
        presence = Presence(session, keys, "tester")
        assert presence.wait_for(["predictor"], 60.0) == []
        tracker = TrackerService(TrackerServiceConfig(from_file=recording, wait_for=["predictor"]),
                                 dataclasses.replace(base, role="tracker"))
        try:
            stats = ServiceThread("tracker", tracker.run).start().join(90.0)  # ends after the recording
        finally:
            predictor.stop()
            presence.close()
            for s in subs:
                s.undeclare()
    assert tracker.rejects.total == 0 and sum(stats.refused.values()) == 0
    assert stats.played == stats.frames > human.demos[0].n_samples  # every frame crossed the secure router
    markers = [m for m in human_msgs if isinstance(m, DemoMarker)]
    # the person seen at rest before the reach (the recording's lead), a demonstration of its own; then the reach
    assert [(m.event, m.demo_id, m.class_name) for m in markers] == [
        ("start", 0, AT_REST), ("end", 0, AT_REST), ("start", 1, "live"), ("end", 1, "live")]
    rest = [p for p in posteriors if p.demo_id == 0]
    assert rest and max(p.index for p in rest) == markers[1].n_samples - 1  # predicted from where the person stood
    poses = [m for m in human_msgs if isinstance(m, HumanPose) and m.demo_id == 1]
    # the reach ends once the wrist's last second spreads less than 2 cm (rms): this synthetic reach's slow final
    # approach (minimum-jerk-like) does, before its last samples
    assert len(poses) == markers[-1].n_samples >= 0.5 * human.demos[0].n_samples
    # the predictor took the reach's poses (the first ones arrive at once, the reach known only then: it predicts
    # for the newest of a burst) up to the last, and answered with its belief and occupancy
    indices = [p.index for p in posteriors if p.demo_id == 1]
    assert max(indices) == len(poses) - 1 and len(indices) >= 0.8 * len(poses)
    assert len([g for g in grids if g.demo_id == 1]) >= 0.8 * len(poses) and all(g.indices.size > 0 for g in grids)
    final = max((p for p in posteriors if p.demo_id == 1), key=lambda p: p.index)
    assert final.class_names[int(np.argmax(final.posterior))] == system_files.human_class
