"""``foresight bench viz`` times both paths of an occupancy update, and both draw the same voxels."""

from __future__ import annotations

import json

import numpy as np

from services.bench import main as bench_main
from shared.foxglove.bench import bench_occupancies, dumps_sliced, json_occupancy, main
from shared.foxglove.decode import SchemaDecoder
from shared.foxglove.scene import SceneBuilder
from shared.foxglove.stream import SceneStream
from shared.scene import load_scene

SCENE = load_scene(None)


def test_bench_writes_both_paths_with_the_same_voxels(tmp_path, capsys) -> None:
    out = tmp_path / "viz.json"
    assert main(["--updates", "3", "--voxels", "500", "--json-out", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "json: cubes as JSON (baseline, replaced)" in printed and "sdk: PointCloud protobuf" in printed
    res = json.loads(out.read_text())
    assert set(res["paths"]) == set(res["summary"]) == {"json", "sdk"}
    for path in res["paths"].values():
        assert len(path["cpu_ms"]) == len(path["wall_ms"]) == len(path["bytes"]) == 3
        assert all(b > 0 for b in path["bytes"]) and path["file_bytes"] > 0
    # read back from each file: every update's cubes (JSON) are its cloud's points (SDK), about as many as asked
    cubes, points = res["paths"]["json"]["items"], res["paths"]["sdk"]["items"]
    assert cubes == points and len(cubes) == 3
    assert all(400 <= n <= 600 for n in cubes)


def test_one_update_fewer_than_the_warm_ups_is_timed_and_the_file_size_counts_every_update(tmp_path) -> None:
    out = tmp_path / "viz.json"
    assert main(["--updates", "1", "--voxels", "50", "--grid", "16", "--json-out", str(out)]) == 0
    res = json.loads(out.read_text())
    for name, path in res["paths"].items():
        assert len(path["cpu_ms"]) == len(path["items"]) == 1
        assert path["file_updates"] == 2  # the one occupancy, written once as the warm-up and once timed
        assert res["summary"][name]["file_bytes_per_update"] == path["file_bytes"] / 2


def test_the_file_size_per_update_divides_by_the_warm_ups_too(tmp_path) -> None:
    out = tmp_path / "viz.json"
    assert main(["--updates", "3", "--voxels", "200", "--grid", "16", "--json-out", str(out)]) == 0
    res = json.loads(out.read_text())
    for name, path in res["paths"].items():
        assert path["file_updates"] == 5  # 2 warm-ups + 3 timed
        assert res["summary"][name]["file_bytes_per_update"] == path["file_bytes"] / 5


def test_the_baseline_json_decodes_to_one_cube_per_point_of_the_cloud() -> None:
    (occ,) = bench_occupancies(SCENE, 1, 500, seed=3)
    text = dumps_sliced(json_occupancy(occ, 1.5))
    assert text == json.dumps(json_occupancy(occ, 1.5), separators=(",", ":"))  # sliced: the same text
    (entity,) = json.loads(text)["entities"]
    (m,) = SceneStream(SceneBuilder(SCENE)).draw(occ, 1_500_000_000)
    s = m.schema
    cloud = SchemaDecoder().decode(m.topic, s.name, s.encoding, s.data, m.data)
    assert len(cloud.data) // cloud.point_stride == len(entity["cubes"]) > 0
    # the same voxel centres, in the same order
    xyz = np.frombuffer(cloud.data, np.dtype([("xyz", "<f4", (3,)), ("rest", "V8")]))["xyz"]
    centres = np.array([[c["pose"]["position"][k] for k in "xyz"] for c in entity["cubes"]])
    np.testing.assert_allclose(xyz, centres, atol=1e-6)


def test_foresight_bench_lists_viz(capsys) -> None:
    assert bench_main(["--help"]) == 0
    assert "viz" in capsys.readouterr().out
