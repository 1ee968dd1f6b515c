"""The shared show clock across hosts and apps: an Ableton Link session's beat timeline.

`timeline` is the pure part (a session's beat against Link's clock, Link's clock against the
machine's monotonic one, bar lines by phase); `session` owns the Link peer and samples it on a
thread of its own; `clock` is the show clock a run keeps on it; `start` decides the bar line a
show starts on.
"""
