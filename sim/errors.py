"""Provides `LinkevoError`, the one base of the errors linkevo raises for what it refuses:
bad input (a value, a file, a reference), or a state it will not act on (a damaged
artefact, a store held by another process). Every such error names the value or file,
what is allowed and what to do; the command line prints it and exits 2, with no traceback.

It lives at the bottom of the house so that every layer can derive from it. Errors that
are also a `ValueError` (bad input) derive from both, so library users who catch
`ValueError` keep working.
"""

from __future__ import annotations


class LinkevoError(Exception):
    """Something linkevo refuses; the message says what, what is allowed and what to do."""


class ConfigError(LinkevoError, ValueError):
    """A configuration value (a grid's, or a robot's) that cannot be used: missing, unknown
    or out of range; the message names the key and what is allowed."""
