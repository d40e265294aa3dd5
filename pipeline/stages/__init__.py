"""Stage entry points: one module per ``navreplay`` subcommand and DVC stage.

Each module has ``configure(parser)`` (arguments only) and ``run(args) -> int``, a thin shell
that parses paths from argv, loads inputs, calls a pure typed function and writes atomically.
``options`` (not a subcommand) declares the options they share: ``--params``, ``--out`` and
other directories.
"""
