"""The ``pecli`` command line: one typer module per command group, assembled here."""

from pecli.cli.app import app, main

__all__ = ["app", "main"]
