"""valvebench from Python: the bench server's API with numpy/pandas traces, a private local server on the
embedded emulator when no server is given, and a pytest plugin (valvebench.pytest_plugin).

    import valvebench
    batch = valvebench.Client().run("examples/compare-current-controllers.json")
    currents = batch.channel("i_A")        # DataFrame: t_s index, one column per law, "pi i_A", ...

docs/python.md has the whole API.
"""
from .client import Batch, Client, Comparison, Diagnosis, Progress, Queue, Run, RunList, Trace, load_spec
from .errors import (Error, FailedPrecondition, InvalidArgument, NotFound, PermissionDenied, ResourceExhausted,
                     RunFailed, Unauthenticated, Unavailable)
from .local import LocalServer, default_store_path, find_tool
from .units import channel_unit, metric_unit

__all__ = ["Batch", "Client", "Queue", "RunList", "Comparison", "Diagnosis", "Progress", "Run", "Trace", "load_spec", "Error",
           "FailedPrecondition", "InvalidArgument", "NotFound", "PermissionDenied", "ResourceExhausted",
           "RunFailed", "Unauthenticated", "Unavailable", "LocalServer", "default_store_path", "find_tool",
           "channel_unit", "metric_unit"]
__version__ = "0.1.0"
