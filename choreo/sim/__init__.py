"""The simulated RCB-4 controller: a board model, faults, and a pseudo-terminal server.

- `board.SimBoard`: the board, driven with explicit time (deterministic, no threads).
- `faults`: the fault kinds and their spelling (every K-th frame, or probability P with a seed).
- `line.Line`: framing, line settings and wire time between a client and the board.
- `options`: one parser for the `sim://` query string and `choreo sim`'s options.
- `pty.PtyServer`: the board on a pseudo-terminal (`choreo sim`).

The in-process pyserial port is `choreo.sim.protocol_sim` (`sim://`).
"""
