"""The simulated RCB-4 controller: a board model, faults, and a pseudo-terminal server."""
