"""A run's recording: the MCAP format of the executor's log, in one place.

* :mod:`shared.recording.schemas`: the JSON Schemas of the Foresight message channels and the rejects;
* :mod:`shared.recording.writer`: :class:`~shared.recording.writer.McapLog`, the thread-safe writer the
  executor logs every message with (a killed writer leaves a readable file);
* :mod:`shared.recording.reader`: :func:`~shared.recording.reader.read_log`, a record-by-record reader
  that tolerates a truncated end (used by ``foresight log`` and the tests);
* the scene channels come from :mod:`shared.foxglove` (shared with the live view).

The layout of a log is documented in docs/executor.md.
"""
