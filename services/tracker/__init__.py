"""``foresight tracker``: a live person's body keypoints in, the paper's posture features out (core: :mod:`.core`)."""
