"""Project exceptions. Each also subclasses the builtin a caller would expect to catch."""

from __future__ import annotations


class SwarmError(Exception):
    """Base class of every error this project raises on purpose."""


class ConfigError(SwarmError, ValueError):
    """A scenario file, parameter or CLI flag is invalid; the message names the field and the value."""


class MessageError(SwarmError, ValueError):
    """A wire message failed validation (type, shape, finiteness, schema version)."""


class LogError(SwarmError, ValueError):
    """A recorded sensor log is invalid; the message names the file and, inside it, the line and column."""
