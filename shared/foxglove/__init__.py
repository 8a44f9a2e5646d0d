"""The run as Foxglove sees it: the 3D scene, the plots, the live server and the layout.

* :mod:`shared.foxglove.scene`: :class:`~shared.foxglove.scene.SceneBuilder`, messages -> ``foxglove-sdk``
  well-known messages (``SceneUpdate``, ``FrameTransforms``, ``PointCloud``);
* :mod:`shared.foxglove.charts`: the class posterior and the costs as plot-able JSON messages;
* :mod:`shared.foxglove.stream`: :class:`~shared.foxglove.stream.SceneStream`, which message draws what
  and how often, encoded once for the MCAP log and the live server alike;
* :mod:`shared.foxglove.live`: :class:`~shared.foxglove.live.LiveServer`, Foxglove's WebSocket server;
* :mod:`shared.foxglove.layout`: the Foxglove layout (3D panel, posterior plot, cost plot);
* :mod:`shared.foxglove.decode`: reads the scene channels back with ``protobuf`` and the schemas a file
  carries (tests, ``foresight log snapshot``), independently of the SDK that wrote them.

docs/live-view.md says how to watch a run live and how to open a recorded one.
"""
