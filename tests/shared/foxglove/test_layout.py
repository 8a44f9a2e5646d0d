"""The Foxglove layout: docs/foresight.foxglove.json is the default scene's, and every plotted path exists."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from shared.foxglove.layout import foresight_layout, layout_text, library_class_names
from shared.foxglove.stream import SCHEMAS, SceneStream
from shared.protocol import ClassPosterior

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
    post = posterior()  # over the default library's 8 classes, as the predictor sends it
    post = ClassPosterior(stamp=post.stamp, tick=post.tick, demo_id=post.demo_id, index=post.index,
                          class_names=library_class_names(), posterior=np.full(8, 1 / 8), log_likelihood=np.zeros(8))
    charts = {m.topic: json.loads(m.data) for m in stream.draw(plan(builder.robot), 0) + stream.draw(post, 0)
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


def _plotted(layout: dict, prefix: str) -> list[str]:
    return [s["value"].removeprefix(prefix) for p in panels(layout["content"]) if p["panelType"] == "Plot"
            for s in p["config"]["paths"] if s["value"].startswith(prefix)]


def test_the_documented_layout_plots_every_class_of_the_library_the_demo_runs() -> None:
    """The shipped layout plotted blue_cup and red_cup only: the cups' names, 2 of the default library's 8 classes."""
    from services.replayer.core import ReplayerConfig, load_replay_library

    classes = load_replay_library(ReplayerConfig()).class_names  # what `foresight demo` / `replay` stream
    assert len(classes) == 8
    assert _plotted(json.loads(DOC.read_text()), "/viz/posterior.probability.") == classes
    colours = [s["color"] for p in panels(json.loads(DOC.read_text())["content"]) if p["panelType"] == "Plot"
               for s in p["config"]["paths"] if s["value"].startswith("/viz/posterior.")]
    assert len(set(colours)) == len(classes), "two classes drawn alike"


def test_write_layout_plots_the_classes_of_the_library_given(tmp_path) -> None:
    from services.view.__main__ import main
    from shared.library import MotionLibrary, save_library
    from shared.synthetic import generate_library

    lib = generate_library(n_classes=3, n_demos=1)
    save_library(MotionLibrary(["reach_a", "reach_b", "reach_c"], lib.demos, [], "test"), tmp_path / "lib.npz")
    out = tmp_path / "layout.json"
    assert main(["--write-layout", str(out), "--library", str(tmp_path / "lib.npz")]) == 0
    layout = json.loads(out.read_text())
    assert _plotted(layout, "/viz/posterior.probability.") == ["reach_a", "reach_b", "reach_c"]
    assert _plotted(layout, "/viz/costs.total.") == [c.name for c in SCENE.cups]  # the goals stay the cups


def test_write_layout_names_a_library_that_does_not_read(tmp_path, capsys) -> None:
    from services.view.__main__ import main

    with pytest.raises(SystemExit) as exc:
        main(["--write-layout", str(tmp_path / "layout.json"), "--library", str(tmp_path / "none.npz")])
    assert exc.value.code == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "none.npz" in err[0] and not (tmp_path / "layout.json").exists()
