"""The Foxglove layout: docs/foresight.foxglove.json is the default scene's, and every plotted path exists."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from shared.foxglove.layout import foresight_layout, layout_text
from shared.foxglove.stream import SCHEMAS, SceneStream

from .conftest import SCENE, plan, posterior

DOC = Path(__file__).resolve().parents[3] / "docs" / "foresight.foxglove.json"


def panels(node: dict) -> list[dict]:
    if node.get("type") == "panel":
        return [node]
    return [p for item in node.get("items", []) for p in panels(item["content"])]


def test_the_documented_layout_is_the_default_scenes() -> None:
    assert DOC.read_text() == layout_text(foresight_layout(SCENE)), "regenerate: foresight view --write-layout " \
                                                                     "docs/foresight.foxglove.json"


def test_the_layout_shows_every_scene_topic_and_plots_paths_that_resolve(builder) -> None:
    layout = json.loads(foresight_layout(SCENE).to_json())
    by_type = {p["panelType"]: p for p in panels(layout["content"])}
    three_d = by_type["ThreeDee"]["config"]
    drawn = {t for t, s in SCHEMAS.items() if s.name in ("foxglove.SceneUpdate", "foxglove.PointCloud")}
    assert set(three_d["topics"]) == drawn and all(v["visible"] for v in three_d["topics"].values())
    cloud = three_d["topics"]["/viz/occupancy"]
    assert (cloud["pointShape"], cloud["cubeSize"], cloud["colorMode"]) == ("cube", SCENE.grid.resolution,
                                                                            "rgba-fields")
    stream = SceneStream(builder)
    charts = {m.topic: json.loads(m.data) for m in stream.draw(plan(builder.robot), 0) + stream.draw(posterior(), 0)
              if m.schema.message_encoding == "json"}
    plots = [p for p in panels(layout["content"]) if p["panelType"] == "Plot"]
    assert len(plots) == 2
    for p in plots:
        for series in p["config"]["paths"]:
            topic, _, path = series["value"].partition(".")
            value = charts[topic]
            for part in path.split("."):
                value = value[part]
            assert value is None or isinstance(value, float), series["value"]


def test_a_model_s_own_voxel_size_is_the_layout_s_cube(tmp_path, capsys) -> None:
    """The cubes were the scene grid's 5 cm whatever the model's resolution (foresight train --resolution 0.03)."""
    from services.view.__main__ import main

    cloud = json.loads(foresight_layout(SCENE, voxel_size=0.03).to_json())
    assert next(p for p in panels(cloud["content"]) if p["panelType"] == "ThreeDee")["config"]["topics"][
        "/viz/occupancy"]["cubeSize"] == 0.03
    out = tmp_path / "layout.json"
    assert main(["--write-layout", str(out), "--voxel-size", "0.03"]) == 0
    assert out.read_text() == layout_text(foresight_layout(SCENE, voxel_size=0.03))
    with pytest.raises(SystemExit) as exc:
        main(["--write-layout", str(out), "--voxel-size", "-1"])
    assert exc.value.code == 2 and "view.voxel_size" in capsys.readouterr().err
