"""The experiments ``foresight eval`` runs, with one line each: the one list its help and ``foresight --help`` show.

Kept apart from :mod:`services.experiments.cli` (which imports torch through the experiments) so that
``foresight --help`` lists them without loading any of them.
"""

from __future__ import annotations

__all__ = ["EXPERIMENTS"]

EXPERIMENTS: dict[str, str] = {
    "recognition": "early recognition, leave-one-out (Fig. 6)",
    "novelty": "is a class the model never saw called unfamiliar (leave one class out)",
    "interference": "one robot task against a human reaching across it (Table I)",
    "switch": "two robot tasks, when the robot settles on its goal (Fig. 8-9)",
    "occupancy": "does the predicted occupancy hold where the human really goes (leave-one-out)",
    "volumes": "each occupancy volume in the loop (Table I + switch) against the real human",
    "pace": "Table I across the robot's pace, both protocols: where prediction pays off",
    "all": "all of them and the timings, one Markdown report with PNGs",
}
