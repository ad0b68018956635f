"""Exceptions raised by companion.

Every error that a user can cause (a bad file, key, value or command-line argument) is a
:class:`CompanionError`; the CLI prints its message on one line and exits with code 2.
"""

from __future__ import annotations


class CompanionError(Exception):
    """Base class for errors caused by user input; the message names what was wrong."""


class ConfigError(CompanionError):
    """A parameter or scenario file, key or value is invalid."""


class DataError(CompanionError):
    """A data file (for example a person CSV) is malformed."""


class TransportError(CompanionError):
    """A ROS 2 transport (DDS, Zenoh) could not start: a port in use, no router to reach."""
