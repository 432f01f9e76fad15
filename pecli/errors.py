"""Errors a user can cause. The CLI turns them into one red line and exit code 1."""


class PecliError(Exception):
    """A mistake in the user's input: a bad config, policy name, path or option."""


class ConfigError(PecliError):
    """A scenario file that cannot be read or does not validate; ``problems`` lists every problem found (the
    message names the first)."""

    def __init__(self, message: str, problems: list[str] | None = None) -> None:
        super().__init__(message)
        self.problems = problems or [message]


class PolicyError(PecliError):
    """A policy string that does not resolve, or resolves to the wrong role."""


class ExportError(PecliError):
    """An exported model or its sidecar that is missing, damaged, or does not fit; or an export that fails its check."""
