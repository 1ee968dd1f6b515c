"""Live operation: the controls the console and OSC share (GO, panic, stop), the OSC codec,
its network side, what commands from outside may cost (`limits`) and what the network may
(`osclimits`), and the notifications sent to --osc-notify targets."""
