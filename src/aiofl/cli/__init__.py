"""The ``aiofl`` command line (typer); nothing else in aiofl imports from here."""

from aiofl.cli.app import app, main

__all__ = ["app", "main"]
