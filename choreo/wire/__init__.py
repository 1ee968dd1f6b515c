"""The wire: RCB-4 frames and replies as bytes and values, and the layouts that place a show's
motions in a board's ROM. Pure: no I/O, no clock; everything above builds on it.

Inside, the imports run one way: `protocol` (frames, replies, the RAM map, the bauds, the
document's play sequence) <- `layouts` (where each HTH4 version puts the motions, and the play
sequences that need that) <- `framewords` (frames and replies in words, as a layout reads them).
"""
