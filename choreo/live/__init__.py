"""Live operation: the controls the console and OSC share (GO, panic, stop), the OSC codec,
its network side and its limits, and the notifications sent to --osc-notify targets."""
