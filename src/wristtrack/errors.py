"""Exceptions carrying a one-line, user-facing message (the CLI prints them without traceback)."""


class WristtrackError(Exception):
    """Base of every error wristtrack reports to the user as one clear line."""


class ConfigError(WristtrackError):
    """A configuration file (camera.json, hand.json, ...) is missing, malformed or impossible."""


class InputError(WristtrackError):
    """Input data (a recording, measurements, timestamps) cannot be used as given."""


class InitialisationError(WristtrackError):
    """The tracker could not initialise from the measurements it was given."""
