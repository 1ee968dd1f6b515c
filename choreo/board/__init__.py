"""The board layer: one link per robot (a serial port, frames out, replies in, retries), the
probe that reads a board without moving it, USB latency and the port doctor. It never imports
the simulator: `sim://` is found by package name, like any pyserial URL handler."""
