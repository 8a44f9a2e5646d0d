"""``foresight eval novelty``: leave one class out, flagged unfamiliar or not, and its command's output."""

from __future__ import annotations

import json

import numpy as np
import pytest

from services.predictor.novelty import least_familiarity
from services.predictor.novelty_eval import TRADE_OFF, main, run_novelty
from shared.library import save_library

from .conftest import SMALL


def test_leaving_a_class_out_flags_its_demonstrations_more_than_the_known_ones(small_library):
    res = run_novelty(small_library, SMALL.gmm, progress=False)
    assert [c.name for c in res.classes] == list(small_library.class_names)
    for c in res.classes:
        assert len(c.traces) == len(small_library.by_class(small_library.class_names.index(c.name)))
        assert c.name not in c.taken_for  # the posterior picks a known class, however unlike the motion is
        assert c.threshold(0.0) == c.known_minima.min() and c.known_flagged(0.0) == 0
    assert res.detection() > res.false_alarms()
    assert all(res.detection(a) <= res.detection(b) and res.false_alarms(a) <= res.false_alarms(b)
               for a, b in zip(TRADE_OFF, TRADE_OFF[1:], strict=False))  # a higher quantile flags more of both


def test_through_a_noisy_sensor_every_demonstration_is_scored_as_the_tracker_gives_it(small_library):
    """`--sensor-noise-m`: the known held-out demonstrations (the threshold's) and the left-out ones both go through
    the sensor, so the threshold is calibrated for it: at quantile 0 no known one is flagged."""
    clean = run_novelty(small_library, SMALL.gmm, progress=False)
    noisy = run_novelty(small_library, SMALL.gmm, progress=False, sensor_noise_m=0.02)
    assert noisy.sensor_noise_m == 0.02 and noisy.to_json()["sensor_noise_m"] == 0.02 and clean.sensor_noise_m == 0
    assert "2 cm of noise" in noisy.lines()[0] and "noise" not in clean.lines()[0]
    for c, n in zip(clean.classes, noisy.classes, strict=True):
        assert n.known_flagged(0.0) == 0 and n.threshold(0.0) < c.threshold(0.0)
        assert np.median([least_familiarity(s) for s in n.traces]) < np.median([least_familiarity(s)
                                                                                for s in c.traces])
    # scored against the threshold learnt as recorded, the noisy known demonstrations fall below it (the problem)
    assert sum((n.known_minima < c.threshold(0.05)).mean() for c, n in zip(clean.classes, noisy.classes,
                                                                        strict=True)) / 3 > 0.5


def test_the_command_prints_the_table_and_json_and_draws_the_png(small_library, tmp_path, capsys):
    lib = tmp_path / "lib.npz"
    save_library(small_library, lib)
    png = tmp_path / "novelty.png"
    assert main(["novelty", "--library", str(lib), "--components", "4", "--plot", str(png), "--quiet"]) == 0
    text = capsys.readouterr().out
    assert "unknown motions flagged" in text and "trade-off" in text and png.stat().st_size > 10_000
    assert main(["novelty", "--library", str(lib), "--components", "4", "--plot", str(png), "--quiet",
                 "--json"]) == 0
    got = json.loads(capsys.readouterr().out)
    assert len(got["classes"]) == 3 and [t["quantile"] for t in got["trade_off"]] == list(TRADE_OFF)
    assert np.isclose(got["false_alarms"], sum(c["known_flagged"] for c in got["classes"])
                      / sum(c["known_heldout"] for c in got["classes"]))


@pytest.mark.parametrize("args, said", [(["--quantile", "1"], "--quantile in [0, 1)"),
                                        (["--sensor-noise-m", "-0.1"], "--sensor-noise-m in [0, 1) m"),
                                        (["--library", "missing-dir"], "missing-dir")])
def test_bad_options_are_one_line(args, said, tmp_path, capsys):
    with pytest.raises(SystemExit) as exit_:
        main(["novelty", "--quiet", "--plot", str(tmp_path / "n.png"), *args])
    assert exit_.value.code == 2
    err = capsys.readouterr().err
    assert said in err and "Traceback" not in err
