"""Every size a message declares is bounded, and checked against its payload, before anything is allocated."""

from __future__ import annotations

import struct
import tracemalloc

import msgpack
import numpy as np
import pytest

from services.demo import DemoConfig
from services.executor.config import ExecutorConfig
from services.planner.config import PlannerConfig
from services.planner.stomp import StompConfig
from shared.config import ConfigError
from shared.protocol import (
    REASONS,
    SCHEMA_VERSION,
    ClassPosterior,
    HumanKeypoints,
    HumanPose,
    OccupancyGrid,
    Plan,
    ProtocolError,
    RobotState,
    decode,
    encode,
)
from shared.protocol import limits as L


def _arr(dtype: str, shape: list[int], data: bytes) -> dict:
    return {"dtype": dtype, "shape": shape, "data": data}


def _grid_map(dims: list[int], n: int = 1) -> dict:
    return {"_type": "OccupancyGrid", "_v": 1, "stamp": 1.0, "tick": -1, "tick_last": True, "demo_id": 0,
            "index": 0, "method": "prediction", "resolution": 0.05,
            "origin": _arr("<f8", [3], np.zeros(3).tobytes()),
            "dims": _arr("<i4", [3], np.asarray(dims, np.int32).tobytes()),
            "indices": _arr("<u4", [n], np.arange(n, dtype=np.uint32).tobytes()),
            "values": _arr("|u1", [n], np.full(n, 9, np.uint8).tobytes())}


def _reject(payload: bytes, cls: type) -> ProtocolError:
    with pytest.raises(ProtocolError) as info:
        decode(payload, cls)
    assert info.value.reason in REASONS
    return info.value


def test_grid_declaring_2000_cubed_is_refused_before_allocation():
    # issue 12: this message made the planner allocate 29.8 GiB in to_dense
    err = _reject(msgpack.packb(_grid_map([2000, 2000, 2000]), use_bin_type=True), OccupancyGrid)
    assert err.reason == "too-large" and "OccupancyGrid.dims" in str(err)


def test_to_dense_checks_the_declared_size_itself():
    g = OccupancyGrid(stamp=1.0, tick=-1, tick_last=True, demo_id=0, index=0, method="prediction", resolution=0.1,
                      origin=np.zeros(3), dims=np.array([2000, 2000, 2000], np.int32),
                      indices=np.array([5], np.uint32), values=np.array([3], np.uint8))
    with pytest.raises(ProtocolError, match="exceeds the limits") as info:
        g.to_dense()
    assert info.value.reason == "too-large"


@pytest.mark.parametrize("dims", [[L.MAX_GRID_DIM + 1, 1, 1], [300, 300, 300]])
def test_grid_dims_per_axis_and_cells_bounded(dims):
    assert _reject(msgpack.packb(_grid_map(dims), use_bin_type=True), OccupancyGrid).reason == "too-large"


def test_grid_at_the_limit_decodes():
    side = round(L.MAX_GRID_CELLS ** (1 / 3))
    msg = decode(msgpack.packb(_grid_map([side, side, side]), use_bin_type=True), OccupancyGrid)
    assert msg.cells() == L.MAX_GRID_CELLS


def test_more_voxels_sent_than_the_grid_has():
    err = _reject(msgpack.packb(_grid_map([2, 2, 2], n=9), use_bin_type=True), OccupancyGrid)
    assert "9 voxels sent for a grid of 8" in str(err)


def test_payload_size_bounded_before_unpacking():
    err = _reject(b"\x00" * (L.MAX_PAYLOAD_BYTES + 1), OccupancyGrid)
    assert err.reason == "too-large" and "exceed the limit" in str(err)


@pytest.mark.parametrize("axis,limit", sorted(L.AXIS_LIMITS.items()))
def test_every_named_axis_is_bounded(axis, limit):
    # declared length over the limit with no data behind it: refused as too large, not as a size mismatch
    fields = {"M": (ClassPosterior, "posterior", [limit + 1]), "K": (Plan, "cost_total", [limit + 1]),
              "T": (Plan, "trajectories", [1, limit + 1, 1]), "D": (RobotState, "q", [limit + 1]),
              "N": (OccupancyGrid, "indices", [limit + 1]), "J": (HumanKeypoints, "positions", [limit + 1, 3])}
    cls, name, shape = fields[axis]
    raw = msgpack.unpackb(encode(_valid(cls)), raw=False)
    raw[name] = _arr(raw[name]["dtype"], shape, b"")
    err = _reject(msgpack.packb(raw, use_bin_type=True), cls)
    assert err.reason == "too-large" and f"({axis}) exceeds the limit {limit}" in str(err)


def test_huge_declared_axis_never_overflows():
    raw = msgpack.unpackb(encode(_valid(RobotState)), raw=False)
    raw["q"] = _arr("<f8", [2 ** 63], b"")
    assert _reject(msgpack.packb(raw, use_bin_type=True), RobotState).reason == "too-large"
    raw = msgpack.unpackb(encode(_valid(Plan)), raw=False)
    raw["trajectories"] = _arr("<f4", [2 ** 32, 2 ** 32, 0], b"")  # a product that wraps to 0 in int64
    assert _reject(msgpack.packb(raw, use_bin_type=True), Plan).reason == "too-large"


def test_declared_size_must_match_the_payload():
    raw = msgpack.unpackb(encode(_valid(RobotState)), raw=False)
    raw["q"] = _arr("<f8", [2], np.zeros(3).tobytes())  # says 2, carries 3
    err = _reject(msgpack.packb(raw, use_bin_type=True), RobotState)
    assert err.reason == "shape" and "24 bytes" in str(err)


def test_strings_and_string_lists_bounded():
    raw = msgpack.unpackb(encode(_valid(RobotState)), raw=False)
    raw["reason"] = "x" * (L.MAX_STRING_CHARS + 1)
    assert _reject(msgpack.packb(raw, use_bin_type=True), RobotState).reason == "too-large"
    raw = msgpack.unpackb(encode(_valid(RobotState)), raw=False)
    raw["joint_names"] = ["a", "y" * (L.MAX_STRING_CHARS + 1)]
    assert _reject(msgpack.packb(raw, use_bin_type=True), RobotState).reason == "too-large"


def test_reasons_of_the_decoder():
    assert _reject(b"\x92\x01", RobotState).reason == "malformed"
    assert _reject(encode(_valid(Plan)), RobotState).reason == "wrong-type"
    raw = msgpack.unpackb(encode(_valid(RobotState)), raw=False)
    raw["_v"] = 7
    assert _reject(msgpack.packb(raw, use_bin_type=True), RobotState).reason == "version"
    raw = msgpack.unpackb(encode(_valid(RobotState)), raw=False)
    raw["q"] = _arr("<f8", [2], np.array([np.nan, 0.0]).tobytes())
    assert _reject(msgpack.packb(raw, use_bin_type=True), RobotState).reason == "non-finite"


@pytest.mark.parametrize(("payload", "text"), [
    (b"\xc7\x05\x01hello", "(msgpack ext types are not allowed)"),
    (msgpack.packb({"_type": "HumanPose", "stamp": msgpack.Timestamp(1, 0)}), "(msgpack ext types are not allowed)"),
    (b"\xc1", "(FormatError: a byte that starts no msgpack object)"),
    (b"\x91" * 100_000 + b"\xc0", "(StackError: nested deeper than msgpack's limit)"),
], ids=["ext", "timestamp-ext", "reserved-byte", "deep"])
def test_what_is_not_msgpack_is_malformed_and_says_why(payload, text):
    """An ext type was filed too-large ("exceeds max_ext_len(0)"); a FormatError or StackError said nothing."""
    err = _reject(payload, HumanPose)
    assert err.reason == "malformed" and str(err) == f"message: not valid msgpack {text}"


def _valid(cls: type):
    if cls is RobotState:
        return RobotState(stamp=1.0, tick=-1, joint_names=["a", "b"], goal=0, reached=False, holding=False,
                          reason="", q=np.zeros(2), qd=np.zeros(2))
    if cls is Plan:
        return Plan(stamp=1.0, tick=-1, step=0, goal_names=["g"], joint_names=["a"], dt=0.1, chosen=0,
                    planning_ms=1.0, occupancy_tick=-1, occupancy_index=-1,
                    trajectories=np.zeros((1, 3, 1), np.float32), cost_smoothness=np.zeros(1),
                    cost_obstacle=np.zeros(1), cost_human=np.zeros(1), cost_total=np.zeros(1),
                    valid=np.ones(1, bool))
    if cls is HumanKeypoints:
        return HumanKeypoints(stamp=1.0, tick=-1, frame=0, frame_id="recorder", names=["pelvis"],
                              positions=np.zeros((1, 3)))
    if cls is ClassPosterior:
        return ClassPosterior(stamp=1.0, tick=-1, demo_id=0, index=0, class_names=["a", "b"],
                              posterior=np.array([0.5, 0.5]), log_likelihood=np.zeros(2))
    return OccupancyGrid.from_dense(np.ones((2, 2, 2)), np.zeros(3), 0.1, stamp=1.0, tick=-1, tick_last=True,
                                    demo_id=0, index=0, method="prediction")


def _header(n_fields: int) -> bytes:
    """A msgpack map of ``n_fields`` entries starting with HumanPose's ``_type`` and ``_v``."""
    return bytes([0x80 | n_fields]) + msgpack.packb({"_type": "HumanPose", "_v": SCHEMA_VERSION})[1:]


@pytest.mark.parametrize("junk", [
    b"\xdd" + struct.pack(">I", 1_000_000) + b"\x80" * 1_000_000,  # a million empty maps in one array
    b"\xdc\x01\x00" + (b"\xdc\x01\x00" + b"\x90" * 256) * 256,  # 256 arrays of 256 empty arrays
    b"\x91" * 500_000 + b"\xc0",  # half a million nested one-element arrays
])
def test_a_payload_of_many_small_objects_is_refused_before_they_are_built(junk):
    """Each byte can be a msgpack container (72 bytes as a Python dict): 16 MiB of them was 1.2 GB of objects."""
    payload = _header(3) + msgpack.packb("junk") + junk
    assert len(payload) <= L.MAX_PAYLOAD_BYTES
    tracemalloc.start()
    try:
        with pytest.raises(ProtocolError, match="^message: (too many msgpack objects|not valid msgpack)") as err:
            decode(payload, HumanPose)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert err.value.reason in ("too-large", "malformed")  # the deep nesting: msgpack's own depth limit
    assert peak < 2 * len(payload) + 5_000_000, f"{peak / 1e6:.1f} MB built for a {len(payload) / 1e6:.1f} MB payload"


@pytest.mark.parametrize(("make", "match"), [
    (lambda: ExecutorConfig(step_period_s=120.0), r"executor\.step_period_s: must be in \[0\.001, 60\]"),
    (lambda: ExecutorConfig(step_period_s=0.0005), r"executor\.step_period_s: must be in \[0\.001, 60\]"),
    (lambda: DemoConfig(period_s=100.0), r"demo\.period_s: must be in \[0\.001, 60\]"),
    (lambda: PlannerConfig(stomp=StompConfig(waypoints=5000)), r"planner\.stomp\.waypoints: at most 4096"),
    (lambda: PlannerConfig(min_dt=100.0), r"planner\.min_dt: bad value 100\.0"),
    (lambda: DemoConfig(seed=-1), r"demo\.seed: must be >= 0"),
])
def test_a_config_whose_messages_every_peer_would_refuse_is_refused_itself(make, match):
    """A clock period, a waypoint count or a time step past the wire's limits stalled a run at its timeouts."""
    with pytest.raises(ConfigError, match=match):
        make().validate()
