"""Exceptions raised by armreach. All derive from :class:`ArmReachError`."""

from __future__ import annotations


class ArmReachError(Exception):
    """Base class of every error armreach raises on purpose."""


class URDFError(ArmReachError):
    """A robot description cannot be used: the message names the problem and the fix."""


class BackendUnavailableError(ArmReachError):
    """A physics backend is not installed (or its engine is missing); the message says what to install."""


class PluginError(ArmReachError):
    """A plugin misbehaved: a duplicate name, a bad registration, or an unknown plugin asked for."""


class ActionError(ArmReachError, ValueError):
    """An action has the wrong shape or is not finite; the env's state was left untouched."""


class ConfigError(ArmReachError, ValueError):
    """An env, task or preset option is unknown or out of range."""


class MissingExtraError(ArmReachError, ImportError):
    """An optional part of armreach (training, sweeps) needs packages that are not installed.

    The message names the extra to install, e.g. ``pip install 'armreach[rl]'``.
    """


class DisplayUnavailableError(ArmReachError):
    """A live window (``render_mode="human"``) was asked for with no display; the message says how to get one."""
