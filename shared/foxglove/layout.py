"""The Foxglove layout of a run: the 3D scene beside the class posterior and the costs, built with ``foxglove.layouts``.

:func:`foresight_layout` places a 3D panel (every scene channel on, the occupancy drawn as cubes of the
grid's voxel size coloured by their probability, the camera on the workspace) beside two plots: the class
posterior p(c|xi) per class and the total cost per goal. A plot's series are message paths that name a
class or a goal (``/viz/posterior.probability.near_left``), so the layout is made for a library's classes and a
scene's cups. docs/foresight.foxglove.json is the layout of the default scene and library (``foresight view
--write-layout FILE [--scene NAME] [--library PATH]`` writes one for others).
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import foxglove.layouts as fl
import numpy as np

from shared.scene import Scene

from .scene import goal_rgb
from .stream import SCHEMAS

__all__ = ["foresight_layout", "layout_text", "library_class_names"]


def _hex(rgb: Sequence[float]) -> str:
    return "#" + "".join(f"{round(255 * c):02x}" for c in rgb[:3])


def _plot(title: str, paths: list[tuple[str, str, str]], y_label: str, y_max: float | None = None) -> fl.PlotPanel:
    series = [fl.PlotSeries(value=value, label=label, color=color, enabled=True, timestamp_method="receiveTime")
              for value, label, color in paths]
    return fl.PlotPanel(title=title, config=fl.PlotConfig(paths=series, show_legend=True, legend_display="top",
                                                          y_axis_label=y_label, min_y_value=0.0, max_y_value=y_max,
                                                          x_axis_val="timestamp"))


def library_class_names(library: str | Path | None = None) -> list[str]:
    """The class names of the library the system runs: the posterior plot's series.

    Args:
        library: A directory of ``compound_*.csv`` or a ``.npz`` (what ``foresight replay --library`` streams and
            the model was trained on); None or empty: the embedded synthetic library (``foresight demo``'s default,
            8 classes), named from its goal layout without generating it.

    Raises:
        LibraryError: The library does not read, or none is given and this build has no embedded one.
    """
    from shared.library import LibraryError, load_library

    if library is not None and str(library).strip():
        return list(load_library(library, report=False).class_names)
    try:
        from shared.synthetic import DEFAULT_CLASSES, DEFAULT_LAYOUT, load_layout  # type: ignore[import-not-found]
    except ModuleNotFoundError as exc:
        if exc.name != "shared.synthetic":
            raise
        raise LibraryError("layout: this build has no embedded synthetic library; give the library whose classes "
                           "to plot (--library DIR_OR_NPZ)") from None
    return list(load_layout(DEFAULT_LAYOUT).goal_names[:DEFAULT_CLASSES])  # generate_library's class names


def foresight_layout(scene: Scene, class_names: Sequence[str] | None = None,
                     goal_names: Sequence[str] | None = None, voxel_size: float | None = None) -> fl.Layout:
    """The layout for a run in ``scene``.

    Args:
        scene: The scene (its cups are the goals; its grid's resolution is the voxels' size).
        class_names: The motion classes of the posterior plot (default: the embedded library's,
            :func:`library_class_names`). The paper's libraries name two classes after the cups, the synthetic
            one eight after its goal layout.
        goal_names: The goals of the cost plot (default: the cups' names).
        voxel_size: The cube drawn per occupancy voxel (m; default: the scene grid's resolution). A model trained
            at another resolution (``foresight train --resolution``) sends its own voxels.

    Returns:
        The layout; ``layout.to_json()`` is the file the Foxglove app imports.
    """
    cups = [c.name for c in scene.cups]
    classes = list(class_names) if class_names is not None else library_class_names()
    goals = list(goal_names) if goal_names is not None else cups
    topics: dict[str, fl.BaseRendererTopicSettings] = {
        topic: fl.BaseRendererSceneUpdateTopicSettings(visible=True)  # type: ignore[dict-item]
        for topic, s in SCHEMAS.items() if s.name == "foxglove.SceneUpdate"}
    topics["/viz/occupancy"] = fl.BaseRendererPointCloudTopicSettings(
        visible=True, point_shape="cube", cube_size=float(voxel_size or scene.grid.resolution),
        color_mode="rgba-fields")
    centre = (np.asarray(scene.workspace.min, dtype=float) + np.asarray(scene.workspace.max, dtype=float)) / 2
    three_d = fl.ThreeDeePanel(title="scene", config=fl.ThreeDeeConfig(
        follow_tf="world", topics=topics,
        camera_state=fl.ThreeDeeCameraState(distance=3.5, perspective=True, phi=55.0, theta_offset=45.0,
                                            target=(float(centre[0]), float(centre[1]), float(centre[2])),
                                            target_offset=(0.0, 0.0, 0.0))))
    posterior = _plot("class posterior p(c|xi)", [
        (f"/viz/posterior.probability.{name}", name, _hex(goal_rgb(name, k))) for k, name in enumerate(classes)],
        "probability", 1.0)
    costs = _plot("total cost per goal (the least is chosen)", [
        (f"/viz/costs.total.{name}", name, _hex(goal_rgb(name, k))) for k, name in enumerate(goals)], "cost")
    plots = fl.SplitContainer(direction="column", items=[fl.SplitItem(content=posterior), fl.SplitItem(content=costs)])
    return fl.Layout(content=fl.SplitContainer(direction="row", items=[
        fl.SplitItem(proportion=2, content=three_d), fl.SplitItem(proportion=1, content=plots)]))


def layout_text(layout: fl.Layout) -> str:
    """The layout as the file the Foxglove app imports (indented JSON, one trailing newline)."""
    import json

    return json.dumps(json.loads(layout.to_json()), indent=2) + "\n"
