"""Exceptions: every failure is a ``valvebench.Error`` carrying the server's (or the parser's) message, which
starts with the field path for bad input (``conditions.supply_V: must be > 0, got -1``)."""


class Error(Exception):
    """Base class. ``code`` is the gRPC status name (``INVALID_ARGUMENT``, ...) or a local equivalent."""

    code = "UNKNOWN"

    def __init__(self, message, code=None):
        super().__init__(message)
        self.message = message
        if code is not None:
            self.code = code

    def __str__(self):
        return self.message


class InvalidArgument(Error, ValueError):
    """Bad input: a spec, a file, an argument. The message names the field."""

    code = "INVALID_ARGUMENT"


class NotFound(Error, LookupError):
    code = "NOT_FOUND"


class FailedPrecondition(Error):
    """No bench can run the spec, or the run is not in a state for the call (e.g. the trace of a running run)."""

    code = "FAILED_PRECONDITION"


class ResourceExhausted(Error):
    code = "RESOURCE_EXHAUSTED"


class Unauthenticated(Error):
    code = "UNAUTHENTICATED"


class PermissionDenied(Error):
    code = "PERMISSION_DENIED"


class Unavailable(Error, ConnectionError):
    """The server cannot be reached, did not answer in time, or a local tool is missing."""

    code = "UNAVAILABLE"


class RunFailed(Error):
    """A run ended failed, cancelled or interrupted where success was required (``Batch.raise_for_status``)."""

    code = "RUN_FAILED"


_BY_CODE = {c.code: c for c in (InvalidArgument, NotFound, FailedPrecondition, ResourceExhausted, Unauthenticated,
                                PermissionDenied, Unavailable)}
_BY_CODE["DEADLINE_EXCEEDED"] = Unavailable


def from_grpc(err, context=""):
    """grpc.RpcError -> the matching Error subclass; the message keeps the server's field path."""
    try:
        name = err.code().name
        details = err.details() or name
    except Exception:  # not a call error (e.g. a channel error): keep what it says
        name, details = "UNAVAILABLE", str(err)
    msg = (context + ": " + details) if context else details
    return _BY_CODE.get(name, Error)(msg, code=name)
