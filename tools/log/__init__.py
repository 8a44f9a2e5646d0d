"""``foresight log``: inspect, draw and time a run's MCAP log (the command is :mod:`tools.log.cli`)."""
