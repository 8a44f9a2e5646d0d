"""SceneBuilder and SceneStream: the scene of a known state has the expected entities and poses, decoded back
with protobuf and the schema the SDK declares (not with the SDK)."""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest

from shared.foxglove.decode import SceneDecodeError, SchemaDecoder
from shared.foxglove.stream import SCHEMAS, SceneStream, VizMessage
from shared.protocol import DemoMarker, HumanPose

from .conftest import SCENE, occupancy, plan, pose, posterior, state

T = 1_700_000_000_123_456_789  # a receive time (ns)


def decoded(messages):
    """``{topic: decoded message}`` of a list of VizMessage."""
    dec = SchemaDecoder()
    out = {}
    for m in messages:
        s = m.schema
        out[m.topic] = dec.decode(m.topic, s.name, s.encoding, s.data, m.data)
    return out


def xyz(p) -> list[float]:
    return [p.x, p.y, p.z]


def test_static_scene_has_the_table_and_each_cup_where_the_scene_puts_them(builder) -> None:
    got = decoded(SceneStream(builder).static(T))
    ents = {e.id: e for e in got["/viz/scene"].entities}
    assert set(ents) == {"obstacles", *(f"cup/{c.name}" for c in SCENE.cups)}
    assert np.allclose([xyz(c.pose.position) for c in ents["obstacles"].cubes], [b.center for b in SCENE.boxes])
    for cup in SCENE.cups:
        cyl = ents[f"cup/{cup.name}"].cylinders[0]
        assert xyz(cyl.pose.position) == pytest.approx(list(cup.center))
        assert cyl.size.z == pytest.approx(cup.height)
    (tf,) = got["/tf"].transforms
    assert (tf.parent_frame_id, tf.child_frame_id) == ("world", "robot_base")
    assert xyz(tf.translation) == pytest.approx(list(SCENE.robot.base_transform()[:3, 3]))
    assert abs(ents["obstacles"].timestamp.seconds * 10**9 + ents["obstacles"].timestamp.nanos - T) < 1000  # float s


def test_robot_spheres_are_at_the_forward_kinematics_and_orange_while_holding(builder) -> None:
    pr2 = builder.robot
    for holding, red in ((False, 0.75), (True, 1.0)):
        got = decoded(SceneStream(builder).draw(state(pr2, holding), T))
        spheres = got["/viz/robot"].entities[0].spheres
        centers = pr2.sphere_centers(pr2.q_start).numpy().reshape(-1, 3)
        assert np.allclose([xyz(s.pose.position) for s in spheres], centers, atol=1e-6)
        assert np.allclose([s.size.x for s in spheres], 2 * pr2.sphere_radii.numpy(), atol=1e-6)
        assert spheres[0].color.r == pytest.approx(red)
        ee = pr2.end_effector(pr2.q_start).numpy()
        (tf,) = got["/tf"].transforms
        assert tf.child_frame_id == "end_effector" and xyz(tf.translation) == pytest.approx(list(ee[:3, 3]), abs=1e-6)


def test_plan_paths_follow_the_end_effector_the_chosen_one_thick_and_green(builder) -> None:
    pr2 = builder.robot
    p = plan(pr2, chosen=1)
    got = decoded(SceneStream(builder).draw(p, T))
    lines = got["/viz/plan"].entities[0].lines
    assert len(lines) == 2
    assert lines[1].thickness > lines[0].thickness and lines[1].color.g > 0.8  # chosen
    assert lines[0].color.r == lines[0].color.g == 0.5  # invalid: grey
    import torch

    ee = pr2.end_effector(torch.as_tensor(p.trajectories[1])).numpy()[:, :3, 3]
    assert np.allclose([xyz(q) for q in lines[1].points], ee, atol=1e-5)
    costs = got["/viz/costs"]
    assert costs["chosen"] == "red_cup" and costs["step"] == 3
    assert costs["total"] == {"blue_cup": None, "red_cup": 4.0}  # infinite: null (JSON has no infinity)


def test_occupancy_cloud_has_every_voxel_above_the_threshold_at_its_centre(builder) -> None:
    occ = occupancy()
    cloud = decoded(SceneStream(builder).draw(occ, T))["/viz/occupancy"]
    pts = np.frombuffer(cloud.data, dtype=[("xyz", "<f4", (3,)), ("p", "<f4"), ("rgba", "u1", (4,))])
    values = occ.values.astype(np.float64) / 255
    kept = values >= 0.05
    assert len(pts) == kept.sum() == 6 * 8 * 7 and cloud.point_stride == 20 and cloud.frame_id == "world"
    ijk = np.stack(np.unravel_index(occ.indices[kept].astype(np.int64), tuple(occ.dims)), axis=-1)
    assert np.allclose(pts["xyz"], occ.origin + occ.resolution * (ijk + 0.5), atol=1e-6)
    assert np.allclose(pts["p"], values[kept], atol=1e-6)
    assert (pts["rgba"][:, 0] == 255).all() and (pts["rgba"][:, 2] == 0).all()  # yellow to red


def test_human_body_and_posterior(builder) -> None:
    got = decoded(SceneStream(builder).draw(pose(), T) + SceneStream(builder).draw(posterior(), T))
    lines = got["/viz/human"].entities[0].lines
    assert len(lines) == len(builder.human.capsules(np.zeros(12))[1]) and all(len(ln.points) == 2 for ln in lines)
    post = got["/viz/posterior"]
    assert post["probability"] == {"blue_cup": 0.25, "red_cup": 0.75}
    assert post["recognised"] == "red_cup" and post["index"] == 40
    assert post["familiar"] is True and post["familiarity"] == 0.0
    unlike = decoded(SceneStream(builder).draw(dataclasses.replace(posterior(), familiar=False, familiarity=-75.5), T))
    assert unlike["/viz/posterior"]["familiar"] is False and unlike["/viz/posterior"]["familiarity"] == -75.5


def test_a_demonstrations_end_draws_its_last_body_again_in_grey(builder) -> None:
    """A live tracker publishes poses during reaches only: its last reach's body stayed on show as if live."""
    from shared.foxglove.scene import ENDED_HUMAN_RGBA, HUMAN_RGBA, SceneBuilder

    def marker(event: str, demo_id: int = 1, stamp: float = 1.01) -> DemoMarker:
        return DemoMarker(stamp=stamp, tick=5, demo_id=demo_id, event=event, true_class=-1, class_name="",
                          n_samples=1)

    def rgba(color) -> tuple:  # noqa: ANN001
        return tuple(round(v, 3) for v in (color.r, color.g, color.b, color.a))

    stream = SceneStream(builder, viz_period_s=0.5)
    assert stream.due(marker("end", demo_id=7)) == "/viz/human"
    assert stream.draw(marker("end", demo_id=7), T) == []  # no body of demonstration 7 drawn: nothing
    live = decoded(stream.draw(pose(), T))["/viz/human"].entities[0]
    stream.mark("/viz/human", pose())
    assert stream.due(marker("start")) is None and stream.draw(marker("start"), T) == []
    end = marker("end")
    assert stream.due(end) == "/viz/human"  # within the throttle's period of the pose: drawn all the same
    stream.mark("/viz/human", end)
    ended = decoded(stream.draw(end, T))["/viz/human"].entities[0]
    assert ended.id == live.id == "human/body" and len(ended.lines) == len(live.lines)
    assert [[(p.x, p.y, p.z) for p in ln.points] for ln in ended.lines] == \
        [[(p.x, p.y, p.z) for p in ln.points] for ln in live.lines]
    assert {rgba(ln.color) for ln in live.lines} == {tuple(round(v, 3) for v in HUMAN_RGBA)}
    assert {rgba(ln.color) for ln in ended.lines} == {tuple(round(v, 3) for v in ENDED_HUMAN_RGBA)}
    lost = marker("lost")  # a reach the tracker lost: no pose updates that body either
    assert stream.due(lost) == "/viz/human"
    assert {rgba(ln.color) for ln in decoded(stream.draw(lost, T))["/viz/human"].entities[0].lines} == \
        {tuple(round(v, 3) for v in ENDED_HUMAN_RGBA)}
    later = pose()
    later.stamp = 1.505  # the marker held back no pose: the next one is due a period after the last pose (1.0)
    assert stream.due(later) == "/viz/human"
    assert SceneBuilder(SCENE).human_ended(end) is None  # no human model


def test_the_robot_human_and_occupancy_are_throttled_plans_and_posteriors_are_not(builder) -> None:
    stream = SceneStream(builder, viz_period_s=0.5)
    occ = occupancy()
    assert stream.due(occ) == "/viz/occupancy"
    stream.mark("/viz/occupancy", occ)
    occ.stamp = 1.4
    assert stream.due(occ) is None
    occ.stamp = 1.5
    assert stream.due(occ) == "/viz/occupancy"
    occ.stamp = 0.2  # a new run's clock went back: drawn
    assert stream.due(occ) == "/viz/occupancy"
    p = plan(builder.robot)
    stream.mark("/viz/plan", p)
    assert stream.due(p) == "/viz/plan" and stream.due(posterior()) == "/viz/posterior"


def test_every_topic_has_a_schema_and_a_bad_message_is_named() -> None:
    assert {s.message_encoding for s in SCHEMAS.values()} == {"protobuf", "json"}
    s = SCHEMAS["/viz/occupancy"]
    with pytest.raises(SceneDecodeError, match="/viz/occupancy"):
        SchemaDecoder().decode("/viz/occupancy", s.name, s.encoding, s.data, b"\xff\xff\xff")
    with pytest.raises(SceneDecodeError, match="not protobuf or jsonschema"):
        SchemaDecoder().decode("/x", "x", "flatbuffer", b"", b"")
    json.loads(SCHEMAS["/viz/costs"].data)


def test_the_base_transform_is_right_at_a_half_turn_about_a_tilted_axis(builder, monkeypatch) -> None:
    a = np.array([1.0, -1.0, 0.0]) / np.sqrt(2.0)
    t = np.eye(4)
    t[:3, :3], t[:3, 3] = 2.0 * np.outer(a, a) - np.eye(3), [0.1, 0.2, 0.3]  # 180 degrees about a
    monkeypatch.setattr(type(builder.scene.robot), "base_transform", lambda _self: t)
    (tf,) = decoded(SceneStream(builder).static(T))["/tf"].transforms  # decoded with the SDK's schema
    q = tf.rotation
    w, v = q.w, np.array([q.x, q.y, q.z])
    back = (w * w - v @ v) * np.eye(3) + 2.0 * np.outer(v, v) + 2.0 * w * np.cross(np.eye(3), v)
    assert np.allclose(back, t[:3, :3], atol=1e-12)  # signs from the off-diagonal differences gave an error of 2


def test_the_human_is_placed_from_its_first_pose_even_when_that_pose_is_not_drawn() -> None:
    from shared.foxglove.scene import default_builder

    def at(demo: int, index: int, stamp: float, shift: float) -> HumanPose:
        f = pose().features.copy()
        f[:2] += shift  # the pelvis walks: the placement reference matters
        return HumanPose(stamp=stamp, tick=-1, tick_last=True, demo_id=demo, index=index, features=f)

    viewed, reference = default_builder(SCENE), default_builder(SCENE)
    stream = SceneStream(viewed, viz_period_s=0.5)
    drawn = []
    for p in (at(1, 7, 0.95, 0.0), at(2, 0, 1.0, 0.3), at(2, 1, 1.5, 0.4)):  # demo 2's first pose comes too soon
        topic = stream.due(p)
        if topic is not None:
            stream.mark(topic, p)
            drawn.append(p.index)
            body = decoded(stream.draw(p, T))["/viz/human"].entities[0].lines
    assert drawn == [7, 1]
    reference.human_body(at(2, 0, 1.0, 0.3))
    want = decoded([VizMessage("/viz/human", reference.human_body(at(2, 1, 1.5, 0.4)).encode(), T)])
    assert [xyz(q) for ln in body for q in ln.points] == [xyz(q) for ln in want["/viz/human"].entities[0].lines
                                                          for q in ln.points]
    for demo in range(3, 10):  # a long session keeps a few references, not one per demonstration
        viewed.note_pose(at(demo, 0, float(demo), 0.0))
    assert len(viewed._first_pose) <= 4
    for demo in range(10, 60):  # joined each demonstration after its first pose: one reference per demonstration
        viewed.human_body(at(demo, 5, float(demo), 0.0))  # was kept for ever
    assert len(viewed._first_pose) <= 4
    # a restarted replayer numbers its reaches from 1 again: the newest reference is the one that places the human
    fresh = default_builder(SCENE)
    for demo in (1, 2, 3):
        fresh.note_pose(at(demo, 0, float(demo), 0.0))
    fresh.note_pose(at(1, 0, 4.0, 2.0))
    assert fresh.placement_reference()[0] == pytest.approx(pose().features[0] + 2.0)  # demo 3's, 2 m off, was kept


def test_a_joint_name_mismatch_is_said_once_per_name_list(builder, caplog) -> None:
    """Every robot state (twice: spheres and end effector) and every plan logged the same warning again."""
    from dataclasses import replace

    good = state(builder.robot)
    names = list(good.joint_names)
    wrong, other = replace(good, joint_names=["x", *names[1:]]), replace(good, joint_names=[*names[:-1], "y"])
    with caplog.at_level("WARNING", logger="shared.foxglove.scene"):
        for _ in range(30):
            assert builder.robot_spheres(wrong) is None and builder.end_effector_transform(wrong) is None
        builder.robot_spheres(other)
    warned = [r.getMessage() for r in caplog.records if "do not match" in r.getMessage()]
    assert len(warned) == 2 and "'x'" in warned[0] and "'y'" in warned[1]


def test_a_flat_posterior_s_chart_recognises_no_class_as_the_table_says() -> None:
    """The chart named the top class of a flat posterior ("blue_cup" at 0.15 among 8) where the table said "(flat)"."""
    from services.scenario import belief
    from shared.foxglove.charts import posterior_chart

    names = ["blue_cup", "red_cup", "near_left", "far_left", "near_centre", "near_right", "far_right", "right_edge"]
    for probs in ([0.15] + [0.85 / 7] * 7, [0.26] + [0.74 / 7] * 7, [0.45, 0.3, 0.25], [0.55, 0.45]):
        post = dataclasses.replace(posterior(), class_names=names[:len(probs)], posterior=np.array(probs),
                                   log_likelihood=np.zeros(len(probs)))
        chart = posterior_chart(post, 1.0)
        assert (chart["recognised"] or "(flat)") == belief(post).split(" p=")[0], probs
        assert chart["recognised_probability"] == pytest.approx(max(probs))
    flat = dataclasses.replace(posterior(), class_names=names, posterior=np.array([0.15] + [0.85 / 7] * 7),
                               log_likelihood=np.zeros(8))
    assert posterior_chart(flat, 1.0)["recognised"] == ""
