"""Each message's own invariants and the codec's errors: every bad message is a ProtocolError naming what is wrong."""

from __future__ import annotations

import dataclasses

import msgpack
import numpy as np
import pytest

from shared.protocol import ClassPosterior, HumanKeypoints, OccupancyGrid, ProtocolError, RobotState, decode, encode
from shared.scene import load_scene

from .test_validation import NOW, grid_msg, plan, state


def _raw(msg) -> dict:
    return msgpack.unpackb(encode(msg), raw=False)


@pytest.mark.parametrize(("msg", "field"), [
    (state(joint_names=["torso", "torso"]), "joint_names"),
    (state(joint_names=["torso", ""]), "joint_names"),
    (plan(joint_names=["elbow", "elbow"]), "joint_names"),
    (plan(traj=np.zeros((2, 2, 2), np.float32), goal_names=["g", "g"], valid=np.ones(2, bool), cost_total=np.ones(2),
          cost_human=np.ones(2), cost_obstacle=np.ones(2), cost_smoothness=np.ones(2)), "goal_names"),
    (ClassPosterior(stamp=NOW, tick=-1, demo_id=0, index=0, class_names=["a", "a"], posterior=np.array([0.5, 0.5]),
                    log_likelihood=np.zeros(2)), "class_names"),
    (HumanKeypoints(stamp=NOW, tick=-1, frame=0, frame_id="s", names=["hip", "hip"], positions=np.zeros((2, 3))),
     "names"),
])
def test_names_receivers_key_on_are_distinct(msg, field) -> None:
    """A Plan or RobotState with joints ["j0", "j0"] passed the ROS 2 gateway and went out to ROS 2, whose parsers
    refuse it; a posterior of classes ["a", "a"] was charted as {"a": 0.5}."""
    with pytest.raises(ProtocolError, match=rf"{msg.TYPE}\.{field}: must be distinct and non-empty"):
        encode(msg)


def _empty(dtype: str, *shape: int) -> dict:
    return {"dtype": dtype, "shape": list(shape), "data": b""}


@pytest.mark.parametrize(("raw", "field"), [
    (_raw(state()) | {"joint_names": [], "q": _empty("<f8", 0), "qd": _empty("<f8", 0)}, "RobotState.q"),
    (_raw(plan()) | {"joint_names": [], "trajectories": _empty("<f4", 1, 2, 0)}, "Plan.trajectories"),
])
def test_a_robot_has_at_least_one_joint(raw, field) -> None:
    """A RobotState of no joints (D = 0) decoded and passed every check."""
    with pytest.raises(ProtocolError, match=rf"{field}: has no joints") as info:
        decode(msgpack.packb(raw))
    assert info.value.reason == "invariant"


def test_a_grid_sends_each_voxel_once_and_only_non_zero_ones() -> None:
    """Indices [1, 1] with values [10, 20] decoded, and to_dense kept the last (0.078); docs/protocol.md says only
    voxels of non-zero probability are sent."""
    good = grid_msg(load_scene().grid)
    for indices, values, what in (([1, 1], [10, 20], "indices: must be strictly increasing"),
                                  ([2, 1], [10, 20], "indices: must be strictly increasing"),
                                  ([1, 2], [10, 0], "values: only voxels of non-zero probability")):
        bad = dataclasses.replace(good, indices=np.array(indices, np.uint32), values=np.array(values, np.uint8))
        with pytest.raises(ProtocolError, match=f"OccupancyGrid.{what}"):
            encode(bad)
    assert decode(encode(good), OccupancyGrid).indices.tolist() == good.indices.tolist()


def test_a_bool_array_holds_only_the_bytes_0_and_1() -> None:
    """``valid`` sent as the bytes [200, 0] decoded, passed, and was sent on as b'\\xc8\\x00'."""
    raw = _raw(plan())
    raw["valid"]["data"] = b"\xc8"
    with pytest.raises(ProtocolError, match=r"Plan\.valid: a bool is the byte 0 or 1"):
        decode(msgpack.packb(raw, use_bin_type=True))


def test_unknown_keys_of_two_kinds_are_named_not_a_type_error() -> None:
    """Unknown keys "x" and b"y" raised TypeError ('<' not supported) from sorting them: a decoder bug's traceback."""
    raw = _raw(state())
    raw["x"], raw[b"y"] = 1, 2
    with pytest.raises(ProtocolError, match=r"RobotState: unknown field\(s\) "):
        decode(msgpack.packb(raw, use_bin_type=True))


@pytest.mark.parametrize("change", [{"tick": 2**70}, {"reason": "\ud800"}])
def test_what_msgpack_cannot_encode_is_a_protocol_error(change) -> None:
    """An int past 64 bits raised OverflowError and a lone surrogate UnicodeEncodeError from encode."""
    with pytest.raises(ProtocolError, match=r"RobotState: cannot be encoded \((OverflowError|UnicodeEncodeError)"):
        encode(dataclasses.replace(state(), **change))


def test_robot_state_of_distinct_joints_round_trips() -> None:
    msg = state()
    assert decode(encode(msg), RobotState).joint_names == msg.joint_names
