"""A run's recording: the MCAP format of the executor's log, in one place.

* :mod:`shared.recording.schemas`: the JSON Schemas of every channel (Foresight messages, rejects,
  Foxglove's ``SceneUpdate`` / ``FrameTransforms``) and the Foxglove topics;
* :mod:`shared.recording.writer`: :class:`~shared.recording.writer.McapLog`, the thread-safe writer the
  executor logs every message with (a killed writer leaves a readable file);
* :mod:`shared.recording.reader`: :func:`~shared.recording.reader.read_log`, a record-by-record reader
  that tolerates a truncated end (used by ``foresight log`` and the tests);
* :mod:`shared.recording.foxglove`: the Foxglove conversion, messages -> scene entities for the 3D panel.

The layout of a log is documented in docs/executor.md.
"""
