"""Output: the result Dataset's schema and recording, netCDF archives written atomically, ParaView files.
"""

import contextvars

#: The command or call that is making the current result (set by the command line; else the Python call), for the
#: ``history`` attribute (here, not in results.py: the command sets it before xarray is imported).
invocation: contextvars.ContextVar = contextvars.ContextVar("invocation", default=None)
