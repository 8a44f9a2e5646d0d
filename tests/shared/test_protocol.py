"""The wire contract: every message round-trips; decode rejects bad payloads naming the field."""

from __future__ import annotations

import dataclasses
import re
from pathlib import Path

import msgpack
import numpy as np
import pytest

from shared.protocol import (
    MESSAGE_TYPES,
    SCHEMA_VERSION,
    ClassPosterior,
    ClockTick,
    DemoMarker,
    HumanKeypoints,
    HumanPose,
    Keys,
    Message,
    OccupancyGrid,
    Plan,
    ProtocolError,
    RobotState,
    decode,
    encode,
)

REPO = Path(__file__).resolve().parents[2]
DOC = REPO / "docs" / "protocol.md"


def samples() -> dict[str, Message]:
    rng = np.random.default_rng(0)
    grid = np.zeros((4, 5, 6), dtype=np.float32)
    grid[1, 2, 3] = 0.5
    grid[3, 4, 5] = 1.0
    post = np.array([0.2, 0.3, 0.5])
    points = rng.normal(size=(3, 3))
    points[1] = np.nan  # a point the sensor lost
    return {
        "HumanKeypoints": HumanKeypoints(stamp=1.4, tick=-1, frame=41, frame_id="recorder",
                                         names=["pelvis", "r_wrist", "neck"], positions=points),
        "HumanPose": HumanPose(stamp=1.5, tick=3, tick_last=True, demo_id=2, index=7, features=rng.normal(size=12)),
        "DemoMarker": DemoMarker(stamp=1.0, tick=-1, demo_id=2, event="start", true_class=4, class_name="compound_4",
                                 n_samples=100),
        "ClassPosterior": ClassPosterior(stamp=2.0, tick=-1, demo_id=1, index=5, class_names=["a", "b", "c"],
                                         posterior=post, log_likelihood=np.array([-1.0, -np.inf, -3.0]),
                                         familiarity=-2.5),  # measured, as the predictor's always is: version 2
        "OccupancyGrid": OccupancyGrid.from_dense(grid, np.array([0.1, -0.5, 0.0]), 0.05, stamp=2.0, tick=4,
                                                  tick_last=True, demo_id=1, index=5, method="prediction"),
        "Plan": Plan(stamp=3.0, tick=5, step=5, goal_names=["g0", "g1"], joint_names=[f"j{i}" for i in range(8)],
                     dt=0.1, chosen=1, planning_ms=12.5, occupancy_tick=4, occupancy_index=5,
                     trajectories=rng.normal(size=(2, 10, 8)).astype(np.float32),
                     cost_smoothness=np.array([1.0, 2.0]), cost_obstacle=np.array([0.0, 0.1]),
                     cost_human=np.array([0.5, 0.2]), cost_total=np.array([1.5, 2.3]),
                     valid=np.array([True, True])),
        "RobotState": RobotState(stamp=4.0, tick=6, joint_names=["a", "b"], goal=-1, reached=False, holding=True,
                                 reason="no plan yet", q=np.array([0.1, 0.2]), qd=np.zeros(2)),
        "ClockTick": ClockTick(stamp=0.5, tick=0, period=0.1),
    }


def raw(msg: Message) -> dict:
    return msgpack.unpackb(encode(msg), raw=False)


def pack(d: dict) -> bytes:
    return msgpack.packb(d, use_bin_type=True)


def test_samples_cover_every_message_type():
    assert set(samples()) == set(MESSAGE_TYPES)


@pytest.mark.parametrize("change,match", [
    ({"names": ["pelvis", "neck"]}, "2 names for 3 points"),
    ({"names": ["pelvis", "pelvis", "neck"]}, "distinct"),
    ({"frame": -1}, "frame: must be >= 0"),
    ({"positions": np.array([[0.0, 0.0, np.inf], [0.0] * 3, [0.0] * 3])}, "infinity or a partly NaN point"),
    ({"positions": np.array([[0.0, np.nan, 0.0], [0.0] * 3, [0.0] * 3])}, "infinity or a partly NaN point"),
])
def test_keypoint_invariants(change, match):
    bad = dataclasses.replace(samples()["HumanKeypoints"], **change)
    with pytest.raises(ProtocolError, match=match):
        encode(bad)  # never sent
    d = raw(samples()["HumanKeypoints"])
    d.update({k: v for k, v in change.items() if k != "positions"})
    if "positions" in change:
        p = change["positions"].astype("<f8")
        d["positions"] = {"dtype": p.dtype.str, "shape": list(p.shape), "data": p.tobytes()}
    with pytest.raises(ProtocolError, match=match):
        decode(pack(d), HumanKeypoints)  # nor taken in


@pytest.mark.parametrize("name", sorted(MESSAGE_TYPES))
def test_round_trip(name):
    msg = samples()[name]
    back = decode(encode(msg))
    assert type(back) is type(msg)
    for f in dataclasses.fields(msg):
        a, b = getattr(msg, f.name), getattr(back, f.name)
        if isinstance(a, np.ndarray):
            assert b.dtype == np.dtype(f.metadata["array"].dtype)
            np.testing.assert_array_equal(a, b)
        else:
            assert a == b, f.name
    assert decode(encode(msg), type(msg)) is not None


def test_occupancy_quantisation_and_sparsity():
    msg = samples()["OccupancyGrid"]
    assert msg.indices.tolist() == [(1 * 5 + 2) * 6 + 3, (3 * 5 + 4) * 6 + 5]
    assert msg.values.tolist() == [128, 255]
    dense = msg.to_dense()
    assert dense.shape == (4, 5, 6) and dense[1, 2, 3] == pytest.approx(128 / 255) and dense.sum() == pytest.approx(
        1 + 128 / 255)


def test_truncated_bytes():
    data = encode(samples()["HumanPose"])
    for cut in (1, len(data) // 2, len(data) - 1):
        with pytest.raises(ProtocolError, match="message"):
            decode(data[:cut])


def test_not_a_map_and_unknown_type():
    with pytest.raises(ProtocolError, match="expected a map"):
        decode(pack([1, 2]))
    d = raw(samples()["ClockTick"])
    d["_type"] = "Teleport"
    with pytest.raises(ProtocolError, match=r"message\._type: unknown message type 'Teleport'"):
        decode(pack(d))


def test_expected_type_mismatch():
    with pytest.raises(ProtocolError, match="got ClockTick, expected HumanPose"):
        decode(encode(samples()["ClockTick"]), HumanPose)


def test_wrong_version():
    d = raw(samples()["HumanPose"])
    d["_v"] = SCHEMA_VERSION + 1
    with pytest.raises(ProtocolError, match=r"HumanPose\._v: schema version"):
        decode(pack(d))


def test_version_1_is_still_read_its_posterior_familiar_and_without_the_fields_it_did_not_have():
    for name, msg in samples().items():
        d = raw(msg)
        d["_v"] = 1
        if name == "ClassPosterior":
            with pytest.raises(ProtocolError, match=r"ClassPosterior: unknown field\(s\) 'familiar', 'familiarity'"):
                decode(pack(d))  # a version-1 sender did not know them
            del d["familiar"], d["familiarity"]
            got = decode(pack(d))
            assert got.familiar is True and got.familiarity == 0.0
        else:
            assert encode(decode(pack(d))) == encode(msg)  # the same message, written at version 2
    assert raw(samples()["ClassPosterior"])["_v"] == SCHEMA_VERSION == 2  # what is written


def test_each_message_is_written_with_the_lowest_version_that_holds_it():
    """Every message was written at version 2: a build that reads version 1 refused a HumanPose or a Plan of a newer
    build as much as the posterior whose fields had changed, and a system upgraded one machine at a time stopped at
    the first (the mixed-version review's left-alone item)."""
    msgs = samples()
    for name, msg in msgs.items():
        assert raw(msg)["_v"] == (2 if name == "ClassPosterior" else 1), name
    lost = DemoMarker(stamp=1.0, tick=-1, demo_id=3, event="lost", true_class=-1, class_name="live", n_samples=4)
    assert raw(lost)["_v"] == 2  # the event version 2 added
    unmeasured = dataclasses.replace(msgs["ClassPosterior"], familiarity=0.0)
    assert raw(unmeasured)["_v"] == 1 and "familiar" not in raw(unmeasured)  # at their defaults: version 1 holds it
    assert encode(decode(encode(unmeasured))) == encode(unmeasured)


def test_a_build_that_reads_version_1_reads_what_version_1_can_hold(monkeypatch):
    from shared.protocol import codec

    monkeypatch.setattr(codec, "READABLE_VERSIONS", (1,))  # an older build's reader
    for name, msg in samples().items():
        if name == "ClassPosterior":
            with pytest.raises(ProtocolError, match=r"ClassPosterior\._v: schema version '2'") as err:
                decode(encode(msg))
            assert err.value.reason == "version"
        else:
            decode(encode(msg))


def test_a_version_1_marker_cannot_be_lost_an_event_version_2_added():
    """A version-1 DemoMarker carrying 'lost' was read as a loss (the last note's left-alone item): its sender knew
    no such event."""
    lost = DemoMarker(stamp=1.0, tick=-1, demo_id=3, event="lost", true_class=-1, class_name="live", n_samples=4)
    d = raw(lost)
    assert decode(pack(d)) == lost  # as version 2 writes it
    d["_v"] = 1
    with pytest.raises(ProtocolError, match=r"DemoMarker\.event: 'lost' came with schema version 2; this message is "
                       r"version 1") as err:
        decode(pack(d))
    assert err.value.reason == "version"
    d["event"] = "end"
    assert decode(pack(d)).event == "end"  # version 1's own events still read


@pytest.mark.parametrize("version", [True, 1.0, "1", None])
def test_a_version_that_only_compares_equal_is_refused(version):
    d = raw(samples()["HumanPose"])
    d["_v"] = version
    with pytest.raises(ProtocolError, match=r"HumanPose\._v: schema version") as err:
        decode(pack(d))
    assert err.value.reason == "version"


def test_a_field_the_type_does_not_have_is_refused():
    d = raw(samples()["Plan"])
    d["goal_name"] = ["typo"]
    with pytest.raises(ProtocolError, match=r"^Plan: unknown field\(s\) 'goal_name'$") as err:
        decode(pack(d))
    assert err.value.reason == "malformed"


def test_an_invalid_goal_with_plus_inf_costs_is_accepted():
    plan = samples()["Plan"]
    inf = np.array([np.inf, 1.0])
    ok = dataclasses.replace(plan, valid=np.array([False, True]), cost_smoothness=inf, cost_obstacle=inf,
                             cost_human=inf, cost_total=inf)
    assert decode(encode(ok)).valid.tolist() == [False, True]


@pytest.mark.parametrize(("field", "value", "match"), [
    ("dims", np.array([4.9, 5, 6]), r"OccupancyGrid\.dims: 4\.9 does not fit int32 \(it would be sent as 4\)"),
    ("values", np.array([300, 0], np.int64),
     r"OccupancyGrid\.values: 300 does not fit uint8 \(it would be sent as 44\)"),
])
def test_encode_refuses_a_cast_that_changes_a_value(field, value, match):
    msg = samples()["OccupancyGrid"]
    if field == "values":
        value = np.resize(value, msg.values.shape)
    with pytest.raises(ProtocolError, match=match):
        encode(dataclasses.replace(msg, **{field: value}))
    assert decode(encode(dataclasses.replace(msg, dims=msg.dims.astype(np.float64)))).dims.dtype == msg.dims.dtype


@pytest.mark.parametrize(("field", "value", "match"), [
    ("values", np.int64(300), r"OccupancyGrid\.values: 300 does not fit uint8"),
    ("indices", np.float64(4.9), r"OccupancyGrid\.indices: 4\.9 does not fit uint32"),
])
def test_encode_refuses_a_cast_of_a_0_d_value_too(field, value, match):
    msg = samples()["OccupancyGrid"]  # a 0-d value became 1-d and skipped the check: 300 was sent as 44
    one = dataclasses.replace(msg, indices=msg.indices[:1], values=msg.values[:1])
    with pytest.raises(ProtocolError, match=match):
        encode(dataclasses.replace(one, **{field: value}))


def test_encode_refuses_a_bool_field_that_is_not_0_or_1():
    plan = samples()["Plan"]
    with pytest.raises(ProtocolError, match=r"Plan\.valid: 2 does not fit bool"):
        encode(dataclasses.replace(plan, valid=np.array([1, 2])))
    assert decode(encode(dataclasses.replace(plan, valid=np.array([1, 1])))).valid.dtype == bool


@pytest.mark.parametrize("name", sorted(MESSAGE_TYPES))
def test_missing_field(name):
    msg = samples()[name]
    for f in dataclasses.fields(msg):
        d = raw(msg)
        del d[f.name]
        with pytest.raises(ProtocolError, match=rf"^{name}\.{f.name}: missing$"):
            decode(pack(d))


def test_wrong_dtype():
    d = raw(samples()["HumanPose"])
    d["features"]["dtype"] = "<f4"
    d["features"]["data"] = d["features"]["data"][: 12 * 4]
    with pytest.raises(ProtocolError, match=r"HumanPose\.features: dtype '<f4' where '<f8' \(float64\) is required"):
        decode(pack(d))
    d["features"]["data"] = raw(samples()["HumanPose"])["features"]["data"]
    for other in ("not-a-dtype", "f8,(", ">f8", "=f8", "d", "float64", "<f8" * 40):  # only what encode writes
        d["features"]["dtype"] = other  # "f8,(" made numpy's parser raise SyntaxError, past the decoder
        with pytest.raises(ProtocolError, match=r"HumanPose\.features: dtype .* where '<f8'") as err:
            decode(pack(d))
        assert err.value.reason == "shape"


def test_wrong_shape():
    d = raw(samples()["HumanPose"])
    d["features"]["shape"] = [11]
    with pytest.raises(ProtocolError, match=r"HumanPose\.features: shape \(11,\) axis 0 must be 12"):
        decode(pack(d))
    d["features"]["shape"] = [3, 4]
    with pytest.raises(ProtocolError, match=r"HumanPose\.features: shape \(3, 4\) has 2 axes"):
        decode(pack(d))


def test_shape_symbols_must_agree():
    d = raw(samples()["Plan"])
    d["cost_total"] = {"dtype": "<f8", "shape": [3], "data": np.zeros(3).tobytes()}
    with pytest.raises(ProtocolError, match=r"Plan\.cost_total: .*\(K\) must be 2"):
        decode(pack(d))


def test_data_length_mismatch():
    d = raw(samples()["HumanPose"])
    d["features"]["data"] = d["features"]["data"][:-8]
    with pytest.raises(ProtocolError, match=r"HumanPose\.features: data has 88 bytes"):
        decode(pack(d))


def test_nan_and_inf_rejected():
    msg = samples()["HumanPose"]
    d = raw(msg)
    f = msg.features.copy()
    f[3] = np.nan
    d["features"]["data"] = f.tobytes()
    with pytest.raises(ProtocolError, match=r"HumanPose\.features: contains NaN"):
        decode(pack(d))
    d = raw(msg)
    d["stamp"] = float("inf")
    with pytest.raises(ProtocolError, match=r"HumanPose\.stamp: must be finite"):
        decode(pack(d))
    bad = dataclasses.replace(msg, features=f)
    with pytest.raises(ProtocolError, match=r"HumanPose\.features"):
        encode(bad)  # bad data never leaves


def test_wrong_scalar_types():
    d = raw(samples()["HumanPose"])
    d["index"] = "7"
    with pytest.raises(ProtocolError, match=r"HumanPose\.index: expected an integer, got str"):
        decode(pack(d))
    d = raw(samples()["HumanPose"])
    d["tick_last"] = 1
    with pytest.raises(ProtocolError, match=r"HumanPose\.tick_last: expected a boolean"):
        decode(pack(d))
    d = raw(samples()["ClassPosterior"])
    d["class_names"] = ["a", 2, "c"]
    with pytest.raises(ProtocolError, match=r"ClassPosterior\.class_names: expected a list of strings"):
        decode(pack(d))


def test_invariants():
    s = samples()
    cases = [
        (dataclasses.replace(s["DemoMarker"], event="middle"), r"DemoMarker\.event: must be one of 'start', 'end', "
                                                               r"'lost', got 'middle'"),
        (dataclasses.replace(s["ClassPosterior"], posterior=np.array([0.5, 0.5, 0.5])), r"ClassPosterior\.posterior"),
        (dataclasses.replace(s["ClockTick"], tick=-2), r"ClockTick\.tick"),
        (dataclasses.replace(s["ClockTick"], period=0.0), r"ClockTick\.period"),
        (dataclasses.replace(s["HumanPose"], index=-1), r"HumanPose\.index"),
        (dataclasses.replace(s["Plan"], chosen=2), r"Plan\.chosen"),
        (dataclasses.replace(s["RobotState"], joint_names=["a"]), r"RobotState\.joint_names"),
        (dataclasses.replace(s["OccupancyGrid"], method="guess"), r"OccupancyGrid\.method"),
        (dataclasses.replace(s["Plan"], trajectories=np.zeros((2, 1, 8), np.float32)),
         r"Plan\.trajectories: has 1 waypoint\(s\) per trajectory; at least 2"),
        (dataclasses.replace(s["Plan"], trajectories=np.zeros((2, 0, 8), np.float32)), r"Plan\.trajectories"),
        (dataclasses.replace(s["Plan"], valid=np.array([False, True])), r"Plan\.cost_smoothness: .* \+inf for invalid"),
    ]
    for msg, pattern in cases:
        with pytest.raises(ProtocolError, match=pattern):
            encode(msg)


def test_keys_under_prefix():
    k = Keys("lab/x")
    assert all(key.startswith("lab/x/") for key in k.data_keys())
    assert len(set(k.data_keys())) == len(MESSAGE_TYPES)
    assert set(k.data_keys().values()) == set(MESSAGE_TYPES.values())
    assert k.alive("replayer") == "lab/x/alive/replayer"


def test_protocol_doc_mentions_every_key_type_and_field():
    text = DOC.read_text()
    for key in Keys("foresight").data_keys():
        assert f"`{key}`" in text, key
    assert "foresight/alive/" in text
    for name, cls in MESSAGE_TYPES.items():
        section = re.search(rf"^### `{name}`$(.*?)(?=^##|\Z)", text, re.M | re.S)
        assert section, f"no section for {name}"
        for f in dataclasses.fields(cls):
            assert f"`{f.name}`" in section.group(1), f"{name}.{f.name} not documented"


def test_protocol_doc_names_every_liveliness_token() -> None:
    declared = set()
    for path in [*REPO.glob("services/**/*.py"), *REPO.glob("shared/**/*.py")]:
        # the service name is Presence's third positional argument (keywords may follow)
        declared |= set(re.findall(r'Presence\(\s*\w+,\s*[\w.]+,\s*"([a-z_]+)"', path.read_text()))
    assert {"replayer", "predictor", "planner", "executor", "demo"} <= declared
    doc = DOC.read_text()
    line = next(ln for ln in doc.splitlines() if ln.startswith("Service names:"))
    named = set(re.findall(r"`([a-z_]+)`", line))
    assert declared == named, (declared, named)
