"""The authors' own measured runs, to set the paper protocol's results beside.

From jmainpri/gmm-gmr ``costs_motions.m`` (its one commit, 93e9466, 2016-02-16). The file labels its blocks
"Human motion 0..4" and "Two Cup", not by planner: the block whose means are 0.4-0.7 is read as least
penetration and the one whose means are 21-28 as basic STOMP (their means are the paper's Table I, which
names them); of the two plotted 20-step trace sets of "Two Cup", the one whose costs cross at step 4 is read as
the prediction run and the one that changes from step 14 as the current occupancy (the paper's Fig. 9: 4 against
13). The traces are each goal's best path cost per step (``printCosts()``), in the authors' units: the
prediction-cost integral along the path plus 0.002 x its length.
"""

from __future__ import annotations

import numpy as np

__all__ = ["TABLE1_RUNS", "FIG9_TRACES", "table1_summary"]

TABLE1_RUNS: dict[str, tuple[tuple[float, ...], ...]] = {
    "least_penetration": (
        (0.0641594, 0.307911, 0.0766864, 0.603591, 0.456271, 0.421783, 0.758098, 0.389314, 0.683081, 0.414202),
        (0.500062, 0.588208, 0.40351, 0.444505, 0.382382, 0.396125, 0.336525, 0.887423, 0.550336, 0.436341),
        (0.628969, 0.670597, 0.425077, 0.456164, 0.390523, 0.60041, 0.911988, 0.587371, 0.935298, 0.492131),
        (0.841897, 0.426642, 0.144206, 0.668246, 0.498696, 0.274545, 0.0836824, 0.398978, 0.377196, 0.442855),
        (0.550884, 0.562812, 0.397562, 1.09953, 0.707019, 0.420199, 1.09213, 0.409105, 1.3235, 0.869708),
    ),
    "basic": (
        (27.4122, 17.8438, 22.2124, 29.1403, 12.1878, 16.7551, 24.8013, 30.564, 38.2152, 25.0156),
        (20.6704, 24.3381, 16.3452, 22.376, 31.1526, 22.3008, 16.9285, 22.7474, 12.172, 25.731),
        (37.4473, 34.5703, 17.4371, 25.6087, 33.249, 41.3752, 26.1086, 17.1195, 25.3037, 17.0483),
        (26.7581, 21.2532, 31.5389, 33.5341, 18.2525, 25.1194, 16.7143, 24.468, 21.8142, 25.0466),
        (27.9254, 35.1505, 17.2433, 24.4166, 16.3133, 24.3107, 33.7672, 24.4166, 24.5879, 23.2091),
    ),
}
"""Table I's runs: per human motion (ids 25-29: compound_1 #0-4), 10 runs per planner."""

FIG9_TRACES: dict[str, dict[int, tuple[float, ...]]] = {
    "prediction": {
        0: (0.00181813, 0.00167872, 0.0265973, 0.448542, 0.383505, 0.339955, 0.321021, 0.304216, 0.223452, 0.215249,
            0.237955, 0.229748, 0.200707, 0.211694, 0.204162, 0.206481, 0.209649, 0.149836, 0.150318, 0.146941),
        1: (1.55956, 0.973761, 0.536696, 0.0483653, 0.0158306, 0.00246456, 0.00227421, 0.00326298, 0.0511887,
            0.0451407, 0.0022935, 0.00148322, 0.00132019, 0.00119332, 0.00110118, 0.000888907, 0.000724066,
            0.000567379, 0.000493693, 0.000527242),
    },
    "current": {
        0: (0.00184612, 0.0017111, 0.00153854, 0.00138368, 0.0012314, 0.00106551, 0.000977689, 0.000797317,
            0.00065787, 0.00049616, 0.000659307, 0.000588842, 0.000485476, 0.0129632, 0.160168, 0.473044, 1.15726,
            0.934127, 0.851457, 0.851101),
        1: (0.00308516, 0.00294186, 0.00281392, 0.00267276, 0.00255338, 0.00241864, 0.00230245, 0.00221372,
            0.00216266, 0.0020548, 0.0020258, 0.00205097, 0.00218548, 0.00209348, 0.00189902, 0.00176737, 0.00158443,
            0.00144275, 0.00128897, 0.00110487),
    },
}
"""Fig. 9: each goal's (0, 1) best path cost at each of the 20 steps, per planner (motion 77: compound_3 #2)."""


def table1_summary(planner: str) -> list[dict[str, float]]:
    """Per motion of the authors' Table I: ``mean``, ``std`` (sample), ``min`` and ``max`` of the 10 runs."""
    out = []
    for runs in TABLE1_RUNS[planner]:
        a = np.asarray(runs)
        out.append({"mean": float(a.mean()), "std": float(a.std(ddof=1)), "min": float(a.min()), "max": float(a.max())})
    return out
