"""Subcommands of the ``iloci`` CLI, one module each (see :mod:`iloci.cli`)."""
