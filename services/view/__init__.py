"""``foresight view``: a running system served live to the Foxglove app (core: :mod:`.core`, loop: :mod:`.service`)."""
