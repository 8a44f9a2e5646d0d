"""The model's pictures: swept volumes and a prediction sequence, for 0/1 and for probability volumes."""

from __future__ import annotations

import pytest

from services.predictor.plots import plot_prediction_sequence, plot_swept_volumes

PNG = b"\x89PNG\r\n\x1a\n"


@pytest.mark.parametrize("which", ["small_model", "paper_model"])
def test_both_pictures_of_a_model_are_drawn_whatever_its_volume(which, request, small_library, scene,
                                                                tmp_path) -> None:
    """A model of probability volumes (the trainer's default) ended in a TypeError: ``vol & (share == m)``."""
    model = request.getfixturevalue(which)
    volumes = plot_swept_volumes(model, scene, small_library, tmp_path / "swept.png")
    demo = small_library.demos[0]
    sequence = plot_prediction_sequence(model, scene, demo.features, demo.label, tmp_path / "sequence.png")
    assert volumes.read_bytes()[:8] == PNG and sequence.read_bytes()[:8] == PNG
