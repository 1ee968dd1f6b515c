"""choreo: a show runner for Kondo humanoid robots on an RCB-4 controller.

Kept import-light on purpose: `choreo --help` and `choreo validate` must answer fast, so the
heavy modules (serial, mcap, jsonschema) are imported only by the code paths that use them.
"""

__version__ = "0.1.0"
SCHEMAS = "choreo.schemas"  # the JSON Schemas shipped with choreo: the show format's and the log's
