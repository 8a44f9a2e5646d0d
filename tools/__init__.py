"""Foresight's command-line tools: the ``foresight`` dispatcher and the commands that are no service.

* :mod:`tools.foresight`: ``foresight COMMAND ...`` (also ``python -m tools``), which loads each
  command's module by name;
* :mod:`tools.router`: ``foresight router``, a Zenoh router on loopback;
* :mod:`tools.library`: ``foresight library SUBCOMMAND``, motion libraries;
* :mod:`tools.log`: ``foresight log SUBCOMMAND`` on a run's MCAP log;
* :mod:`tools.reach`: ``python -m tools.reach LIBRARY``, a library's reach points drawn in a scene.

``foresight --help`` lists every sub-command (from each module's table of them). The services import
nothing from here; what the tools share with them lives in ``shared/``.
"""
