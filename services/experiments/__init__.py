"""The paper's experiments, run through the product (``foresight eval``).

- ``harness``: one lock-step run of the four services in-process over loopback Zenoh.
- ``measures``: the paper's interference measure and the clearance to the real human.
- ``heldout``: which class reaches which cup; models trained without the run's demonstrations.
- ``planners``: the compared planners (basic STOMP, least penetration, current occupancy) and timing.
- ``interference``: Table I. ``switch``: Fig. 8-9. ``plots``: Table I's picture.
- ``report``: ``foresight eval all``, every experiment into one Markdown report.
- ``cli``: the ``foresight eval`` command.
"""
