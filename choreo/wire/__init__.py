"""The wire: RCB-4 frames and replies as bytes and values, and the layouts that place a show's
motions in a board's ROM. Pure: no I/O, no clock; everything above builds on it."""
