"""Subcommands of the ``rimd`` command, one module each (``add_arguments(parser)`` and ``main(args)``)."""
